//! Image loading and colour → luma conversion.
//!
//! Luma is ITU-R BT.601, `Y = 0.299 R + 0.587 G + 0.114 B`, computed in 16-bit fixed point
//! exactly as Pillow's `Image.convert("L")` (the conversion pykitti's `mode='L'` uses):
//!
//! `Y = (19595 R + 38470 G + 7471 B + 32768) >> 16`
//!
//! The weights sum to 65536, so grey stays grey (`R = G = B = v` → `Y = v`) and white stays
//! 255. Matching Pillow bit for bit lets a Python reference read the same pixels. Grey
//! 8-bit images are used as they are; 16-bit grey is reduced the way the `image` crate does.

use std::path::Path;

use image::{DynamicImage, GrayImage};

use super::DatasetError;

/// BT.601 luma of one RGB pixel (Pillow's fixed-point formula; see the module docs).
#[inline]
pub fn luma_bt601(r: u8, g: u8, b: u8) -> u8 {
    ((19595 * u32::from(r) + 38470 * u32::from(g) + 7471 * u32::from(b) + 32768) >> 16) as u8
}

/// Converts a decoded image to 8-bit luma: 8-bit grey as is, colour through [`luma_bt601`]
/// (alpha ignored), other formats via 8-bit RGB.
pub fn to_luma(img: DynamicImage) -> GrayImage {
    match img {
        DynamicImage::ImageLuma8(g) => g,
        DynamicImage::ImageLuma16(_) | DynamicImage::ImageLumaA8(_) => img.into_luma8(),
        other => {
            let rgb = other.into_rgb8();
            let (w, h) = rgb.dimensions();
            let data = rgb.pixels().map(|p| luma_bt601(p[0], p[1], p[2])).collect();
            // The buffer holds exactly w·h bytes by construction.
            GrayImage::from_raw(w, h, data).unwrap_or_else(|| GrayImage::new(w, h))
        }
    }
}

/// Decodes an image file to luma; errors name the file.
pub fn load_luma_file(path: &Path) -> Result<GrayImage, DatasetError> {
    let reader = image::ImageReader::open(path).map_err(|e| DatasetError::io(path, &e))?;
    let reader = reader
        .with_guessed_format()
        .map_err(|e| DatasetError::ImageDecode { path: path.to_path_buf(), msg: e.to_string() })?;
    let img = reader
        .decode()
        .map_err(|e| DatasetError::ImageDecode { path: path.to_path_buf(), msg: e.to_string() })?;
    Ok(to_luma(img))
}

/// Reads only an image's header: (width, height).
pub fn image_size(path: &Path) -> Result<(u32, u32), DatasetError> {
    if !path.is_file() {
        return Err(DatasetError::MissingFile { path: path.to_path_buf() });
    }
    image::image_dimensions(path)
        .map_err(|e| DatasetError::ImageDecode { path: path.to_path_buf(), msg: e.to_string() })
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::{Rgb, RgbImage};

    #[test]
    fn greys_and_extremes_are_preserved() {
        for v in 0..=255u8 {
            assert_eq!(luma_bt601(v, v, v), v);
        }
        assert_eq!(luma_bt601(255, 0, 0), 76);
        assert_eq!(luma_bt601(0, 255, 0), 150);
        assert_eq!(luma_bt601(0, 0, 255), 29);
    }

    /// Values computed with Pillow 13 (`Image.new("RGB",(1,1),c).convert("L")`).
    #[test]
    fn matches_pillow() {
        let cases = [
            ((12, 200, 77), 130),
            ((255, 128, 0), 151),
            ((1, 2, 3), 2),
            ((100, 50, 200), 82),
            ((254, 1, 128), 91),
        ];
        for ((r, g, b), y) in cases {
            assert_eq!(luma_bt601(r, g, b), y, "({r},{g},{b})");
        }
    }

    /// Within one level of the rounded float formula everywhere (exhaustive over a lattice).
    #[test]
    fn close_to_float_bt601() {
        for r in (0..=255u8).step_by(3) {
            for g in (0..=255u8).step_by(5) {
                for b in (0..=255u8).step_by(7) {
                    let f = (0.299 * f64::from(r) + 0.587 * f64::from(g) + 0.114 * f64::from(b))
                        .round();
                    assert!((f64::from(luma_bt601(r, g, b)) - f).abs() <= 1.0);
                }
            }
        }
    }

    #[test]
    fn colour_image_converts_per_pixel() {
        let mut img = RgbImage::new(2, 1);
        img.put_pixel(0, 0, Rgb([255, 0, 0]));
        img.put_pixel(1, 0, Rgb([12, 200, 77]));
        let g = to_luma(DynamicImage::ImageRgb8(img));
        assert_eq!(g.as_raw(), &vec![76, 130]);
    }
}
