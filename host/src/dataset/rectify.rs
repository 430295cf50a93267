//! Stereo rectification of a calibrated pinhole pair with radial-tangential distortion, as
//! OpenCV's `stereoRectify` (Bouguet's method, `CALIB_ZERO_DISPARITY`) and
//! `initUndistortRectifyMap` + `remap` (bilinear) do it; used for EuRoC, whose images are
//! distorted and not rectified.
//!
//! * Distortion (`radial-tangential`, OpenCV's `k1 k2 p1 p2`) of normalised coordinates
//!   `(x, y)`, `r² = x² + y²`:
//!   `x_d = x (1 + k1 r² + k2 r⁴) + 2 p1 x y + p2 (r² + 2x²)`,
//!   `y_d = y (1 + k1 r² + k2 r⁴) + p1 (r² + 2y²) + 2 p2 x y`.
//!   The inverse ([`PinholeRadtan::undistort`]) is Newton's method from `(x_d, y_d)`, iterated
//!   until the distorted point is reproduced to 1e-12 (OpenCV stops after 5 fixed-point
//!   steps, so its corners can differ from these by a few 0.01 px for strong distortion).
//! * Rectifying rotations: with `X₁ = R X₀ + T` (camera 0 to camera 1), each camera is turned
//!   half way, `r = exp(−½ log R)`, `R₀' = rᵀ`, `R₁' = r`; then both by `W`, the rotation that
//!   takes `t = r T` onto the x axis. `R_k = W R_k'` maps camera-`k` coordinates to rectified
//!   ones. The baseline is `|T|`; camera 1 must end up to the right (`t_x < 0`).
//! * Rectified camera, shared by both images: `f = (fy₀ + fy₁) / 2` for both axes; principal
//!   point: for each camera the mean of its four undistorted, rotated image corners projected
//!   with `f` and no offset, subtracted from the image centre `((w−1)/2, (h−1)/2)`; then the
//!   mean over both cameras (zero disparity at infinity).
//! * Scaling (`alpha`): `None` keeps `f` (OpenCV's `alpha = −1`); `Some(a)` scales `f` by
//!   `s = (1 − a) s₀ + a s₁`, where `s₀` makes every rectified pixel come from inside both
//!   source images (the inscribed rectangles of a 9 × 9 grid of undistorted border points, as
//!   OpenCV's `icvGetRectangles`) and `s₁` keeps every source pixel. EuRoC uses `Some(0.0)`:
//!   no black border, which would otherwise give FAST corners that do not move with the scene.
//! * Remap: for each rectified pixel `p`, the source pixel is `K_k · distort(R_kᵀ K_rect⁻¹ p)`,
//!   stored once per camera ([`RemapTable`]); images are sampled bilinearly, with 0 outside
//!   the source image (OpenCV's `BORDER_CONSTANT`).

use image::GrayImage;
use nalgebra::{Matrix2, Matrix3, Vector2, Vector3};
use semloc_core::geom::{so3_exp, so3_log};

use super::StereoCalib;

/// Newton steps [`PinholeRadtan::undistort`] takes at most.
const UNDISTORT_MAX_ITERATIONS: usize = 50;
/// Distorted-coordinate residual (normalised units) at which the inverse has converged.
const UNDISTORT_TOLERANCE: f64 = 1e-12;

/// A pinhole camera with radial-tangential distortion (OpenCV `k1 k2 p1 p2`, no `k3`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PinholeRadtan {
    /// Focal length along x, px.
    pub fx_px: f64,
    /// Focal length along y, px.
    pub fy_px: f64,
    /// Principal point x, px.
    pub cx_px: f64,
    /// Principal point y, px.
    pub cy_px: f64,
    /// Radial coefficients `k1`, `k2` (of `r²`, `r⁴`; `r` in normalised units).
    pub k: [f64; 2],
    /// Tangential coefficients `p1`, `p2`.
    pub p: [f64; 2],
}

impl PinholeRadtan {
    /// Distorts normalised coordinates (see the module docs).
    pub fn distort(&self, x: f64, y: f64) -> (f64, f64) {
        let [k1, k2] = self.k;
        let [p1, p2] = self.p;
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (k1 + k2 * r2);
        (
            x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
            y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y,
        )
    }

    /// The Jacobian of [`distort`](Self::distort) at `(x, y)`.
    fn distort_jacobian(&self, x: f64, y: f64) -> Matrix2<f64> {
        let [k1, k2] = self.k;
        let [p1, p2] = self.p;
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (k1 + k2 * r2);
        let d_radial = 2.0 * (k1 + 2.0 * k2 * r2); // ∂radial/∂x = d_radial·x
        Matrix2::new(
            radial + x * x * d_radial + 2.0 * p1 * y + 6.0 * p2 * x,
            x * y * d_radial + 2.0 * p1 * x + 2.0 * p2 * y,
            x * y * d_radial + 2.0 * p1 * x + 2.0 * p2 * y,
            radial + y * y * d_radial + 6.0 * p1 * y + 2.0 * p2 * x,
        )
    }

    /// The normalised coordinates that [`distort`](Self::distort) maps to `(xd, yd)`, by
    /// Newton's method; `None` when it does not converge (distortion that folds over there).
    pub fn undistort(&self, xd: f64, yd: f64) -> Option<(f64, f64)> {
        let target = Vector2::new(xd, yd);
        let mut x = target;
        for _ in 0..UNDISTORT_MAX_ITERATIONS {
            let (dx, dy) = self.distort(x.x, x.y);
            let residual = Vector2::new(dx, dy) - target;
            if residual.amax() <= UNDISTORT_TOLERANCE {
                // A root where the radial factor is not positive lies on a fold of the
                // distortion (the ray turned inside out): not the camera's ray.
                let r2 = x.norm_squared();
                let radial = 1.0 + r2 * (self.k[0] + self.k[1] * r2);
                return (radial > 0.0).then_some((x.x, x.y));
            }
            let step = self.distort_jacobian(x.x, x.y).try_inverse()? * residual;
            x -= step;
            if !(x.x.is_finite() && x.y.is_finite()) {
                return None;
            }
        }
        None
    }

    /// Pixel → normalised distorted coordinates.
    fn normalise(&self, u: f64, v: f64) -> (f64, f64) {
        ((u - self.cx_px) / self.fx_px, (v - self.cy_px) / self.fy_px)
    }

    /// The undistorted ray (z = 1) of pixel `(u, v)`, if the distortion can be inverted there.
    pub fn undistort_pixel(&self, u: f64, v: f64) -> Option<Vector3<f64>> {
        let (xd, yd) = self.normalise(u, v);
        let (x, y) = self.undistort(xd, yd)?;
        Some(Vector3::new(x, y, 1.0))
    }
}

/// A rectified stereo pair: the shared camera and each camera's rectifying rotation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rectification {
    /// The rectified camera (`fx = fy`), shared by both images, and the baseline, m.
    pub calib: StereoCalib,
    /// Left (camera 0) rectifying rotation: `X_rect = r_left · X_cam0`.
    pub r_left: Matrix3<f64>,
    /// Right (camera 1) rectifying rotation: `X_rect1 = r_right · X_cam1`.
    pub r_right: Matrix3<f64>,
}

/// Bouguet rectification of `left` (camera 0) and `right` (camera 1) with `X₁ = r·X₀ + t`
/// (metres), for images of `size` (width, height) px; see the module docs for `alpha`.
///
/// # Errors
/// A message saying why the pair cannot be rectified for semloc: a zero baseline, a vertical
/// rig, camera 1 on the left of camera 0, distortion that cannot be inverted at the image
/// border, or a result that is not finite.
pub fn stereo_rectify(
    left: &PinholeRadtan,
    right: &PinholeRadtan,
    r: &Matrix3<f64>,
    t: &Vector3<f64>,
    size: (u32, u32),
    alpha: Option<f64>,
) -> Result<Rectification, String> {
    let baseline_m = t.norm();
    if !(baseline_m > 0.0 && baseline_m.is_finite()) {
        return Err(format!("the baseline between the cameras is {baseline_m} m"));
    }
    let half = so3_exp(&(so3_log(r) * -0.5));
    let tr = half * t;
    if tr.x.abs() <= tr.y.abs() {
        return Err(format!(
            "the cameras are stacked vertically (translation {:.4} {:.4} {:.4} m after the \
             half rotations); semloc needs a horizontal stereo pair",
            tr.x, tr.y, tr.z
        ));
    }
    if tr.x >= 0.0 {
        return Err(format!(
            "camera 1 is to the left of camera 0 (x = {:.4} m): swap the cameras",
            -tr.x
        ));
    }
    // W turns t onto −x (OpenCV: uu = (sign t_x, 0, 0), ww = t × uu scaled to the angle).
    let uu = Vector3::new(-1.0, 0.0, 0.0);
    let ww = tr.cross(&uu);
    let nw = ww.norm();
    let w = if nw > 0.0 {
        so3_exp(&(ww * ((tr.x.abs() / baseline_m).acos() / nw)))
    } else {
        Matrix3::identity()
    };
    let r_left = w * half.transpose();
    let r_right = w * half;

    let (width, height) = (f64::from(size.0), f64::from(size.1));
    let mut f = 0.5 * (left.fy_px + right.fy_px);
    let corners =
        [(0.0, 0.0), (width - 1.0, 0.0), (0.0, height - 1.0), (width - 1.0, height - 1.0)];
    let mut centre = Vector2::zeros();
    for (cam, rot) in [(left, &r_left), (right, &r_right)] {
        let mut mean = Vector2::zeros();
        for &(u, v) in &corners {
            let ray = rot * undistort_or_err(cam, u, v)?;
            mean += Vector2::new(ray.x / ray.z, ray.y / ray.z) * (f / 4.0);
        }
        centre += (Vector2::new((width - 1.0) / 2.0, (height - 1.0) / 2.0) - mean) * 0.5;
    }
    if let Some(a) = alpha {
        // Pixel extents of both rectified images at focal length f and principal point
        // `centre`, before scaling: the inscribed (`inner`) and bounding (`outer`) boxes.
        let (mut s0, mut s1) = (f64::NEG_INFINITY, f64::INFINITY);
        for (cam, rot) in [(left, &r_left), (right, &r_right)] {
            let (inner, outer) = rectangles(cam, rot, f, &centre, size)?;
            let (cx, cy) = (centre.x, centre.y);
            let ratios = |b: &[f64; 4]| {
                [
                    cx / (cx - b[0]),
                    cy / (cy - b[1]),
                    (width - 1.0 - cx) / (b[2] - cx),
                    (height - 1.0 - cy) / (b[3] - cy),
                ]
            };
            s0 = ratios(&inner).into_iter().fold(s0, f64::max);
            s1 = ratios(&outer).into_iter().fold(s1, f64::min);
        }
        f *= (1.0 - a) * s0 + a * s1;
    }
    let calib = StereoCalib { fx_px: f, fy_px: f, cx_px: centre.x, cy_px: centre.y, baseline_m };
    let finite = [f, centre.x, centre.y].iter().all(|v| v.is_finite() && *v > 0.0)
        && r_left.iter().chain(r_right.iter()).all(|v| v.is_finite());
    if !finite {
        return Err(format!("the rectified camera is degenerate ({calib:?})"));
    }
    Ok(Rectification { calib, r_left, r_right })
}

fn undistort_or_err(cam: &PinholeRadtan, u: f64, v: f64) -> Result<Vector3<f64>, String> {
    cam.undistort_pixel(u, v).ok_or_else(|| {
        format!("the distortion cannot be inverted at pixel ({u}, {v}): check the coefficients")
    })
}

/// OpenCV's `icvGetRectangles`: a 9 × 9 grid over the image (0..=width, 0..=height)
/// undistorted and rotated into the rectified image (focal `f`, principal point `c`); the
/// inscribed box from the outermost rows and columns, and the bounding box of all, each as
/// `[x0, y0, x1, y1]` px.
fn rectangles(
    cam: &PinholeRadtan,
    rot: &Matrix3<f64>,
    f: f64,
    c: &Vector2<f64>,
    size: (u32, u32),
) -> Result<([f64; 4], [f64; 4]), String> {
    const N: u32 = 9;
    let mut inner = [f64::NEG_INFINITY, f64::NEG_INFINITY, f64::INFINITY, f64::INFINITY];
    let mut outer = [f64::INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY];
    for gy in 0..N {
        for gx in 0..N {
            let u = f64::from(gx) * f64::from(size.0) / f64::from(N - 1);
            let v = f64::from(gy) * f64::from(size.1) / f64::from(N - 1);
            let ray = rot * undistort_or_err(cam, u, v)?;
            let (x, y) = (f * ray.x / ray.z + c.x, f * ray.y / ray.z + c.y);
            outer = [outer[0].min(x), outer[1].min(y), outer[2].max(x), outer[3].max(y)];
            if gx == 0 {
                inner[0] = inner[0].max(x);
            }
            if gx == N - 1 {
                inner[2] = inner[2].min(x);
            }
            if gy == 0 {
                inner[1] = inner[1].max(y);
            }
            if gy == N - 1 {
                inner[3] = inner[3].min(y);
            }
        }
    }
    Ok((inner, outer))
}

/// For every pixel of a rectified image, where to sample the source image (built once per
/// sequence and camera; 8 bytes a pixel).
#[derive(Clone, PartialEq)]
pub struct RemapTable {
    width: u32,
    height: u32,
    /// Source (x, y) in px, row-major over the rectified image.
    map: Vec<[f32; 2]>,
}

impl core::fmt::Debug for RemapTable {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "RemapTable({}x{})", self.width, self.height)
    }
}

impl RemapTable {
    /// The table of camera `cam` with rectifying rotation `rot` into the rectified camera
    /// `rect`, for images of `size` px.
    pub fn new(
        cam: &PinholeRadtan,
        rot: &Matrix3<f64>,
        rect: &StereoCalib,
        size: (u32, u32),
    ) -> Self {
        let back = rot.transpose();
        let mut map = Vec::with_capacity(size.0 as usize * size.1 as usize);
        for v in 0..size.1 {
            for u in 0..size.0 {
                let p = Vector3::new(
                    (f64::from(u) - rect.cx_px) / rect.fx_px,
                    (f64::from(v) - rect.cy_px) / rect.fy_px,
                    1.0,
                );
                let ray = back * p;
                let src = if ray.z > 0.0 {
                    let (xd, yd) = cam.distort(ray.x / ray.z, ray.y / ray.z);
                    [(cam.fx_px * xd + cam.cx_px) as f32, (cam.fy_px * yd + cam.cy_px) as f32]
                } else {
                    [f32::NAN, f32::NAN] // behind the camera: sampled as 0
                };
                map.push(src);
            }
        }
        Self { width: size.0, height: size.1, map }
    }

    /// Where rectified pixel `(u, v)` is sampled from, px (`None` outside the table).
    pub fn source(&self, u: u32, v: u32) -> Option<(f32, f32)> {
        if u >= self.width || v >= self.height {
            return None;
        }
        self.map.get(v as usize * self.width as usize + u as usize).map(|s| (s[0], s[1]))
    }

    /// The rectified image of `src` (which must have the table's size: the caller checks):
    /// bilinear interpolation, 0 where the source pixel lies outside `src`.
    pub fn apply(&self, src: &GrayImage) -> GrayImage {
        let (sw, sh) = src.dimensions();
        let (sw, sh) = (i64::from(sw), i64::from(sh));
        let raw = src.as_raw();
        let at = |x: i64, y: i64| -> f32 {
            if x < 0 || y < 0 || x >= sw || y >= sh {
                0.0
            } else {
                f32::from(raw[(y * sw + x) as usize])
            }
        };
        let data = self
            .map
            .iter()
            .map(|&[x, y]| {
                if !(x > -1.0 && y > -1.0 && x < sw as f32 && y < sh as f32) {
                    return 0; // also NaN
                }
                let (x0, y0) = (x.floor(), y.floor());
                let (ax, ay) = (x - x0, y - y0);
                let (xi, yi) = (x0 as i64, y0 as i64);
                let top = at(xi, yi) * (1.0 - ax) + at(xi + 1, yi) * ax;
                let bottom = at(xi, yi + 1) * (1.0 - ax) + at(xi + 1, yi + 1) * ax;
                (top * (1.0 - ay) + bottom * ay).round().clamp(0.0, 255.0) as u8
            })
            .collect();
        GrayImage::from_raw(self.width, self.height, data)
            .unwrap_or_else(|| GrayImage::new(self.width, self.height))
    }
}

/// The remap tables of both cameras of a rectified pair.
#[derive(Debug, Clone, PartialEq)]
pub struct StereoRemap {
    /// The rectification they implement.
    pub rectification: Rectification,
    /// Camera 0 (left).
    pub left: RemapTable,
    /// Camera 1 (right).
    pub right: RemapTable,
}

impl StereoRemap {
    /// Tables for `left` and `right` rectified by `rect`, images of `size` px.
    pub fn new(
        left: &PinholeRadtan,
        right: &PinholeRadtan,
        rect: &Rectification,
        size: (u32, u32),
    ) -> Self {
        Self {
            rectification: *rect,
            left: RemapTable::new(left, &rect.r_left, &rect.calib, size),
            right: RemapTable::new(right, &rect.r_right, &rect.calib, size),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Matrix4;

    /// EuRoC `mav0/cam0/sensor.yaml` and `cam1/sensor.yaml` (all Machine Hall and Vicon Room
    /// sequences share them).
    pub(crate) const EUROC_T_BS0: [f64; 16] = [
        0.0148655429818,
        -0.999880929698,
        0.00414029679422,
        -0.0216401454975,
        0.999557249008,
        0.0149672133247,
        0.025715529948,
        -0.064676986768,
        -0.0257744366974,
        0.00375618835797,
        0.999660727178,
        0.00981073058949,
        0.0,
        0.0,
        0.0,
        1.0,
    ];
    pub(crate) const EUROC_T_BS1: [f64; 16] = [
        0.0125552670891,
        -0.999755099723,
        0.0182237714554,
        -0.0198435579556,
        0.999598781151,
        0.0130119051815,
        0.0251588363115,
        0.0453689425024,
        -0.0253898008918,
        0.0179005838253,
        0.999517347078,
        0.00786212447038,
        0.0,
        0.0,
        0.0,
        1.0,
    ];

    pub(crate) fn euroc_cams() -> (PinholeRadtan, PinholeRadtan) {
        (
            PinholeRadtan {
                fx_px: 458.654,
                fy_px: 457.296,
                cx_px: 367.215,
                cy_px: 248.375,
                k: [-0.28340811, 0.07395907],
                p: [0.00019359, 1.76187114e-05],
            },
            PinholeRadtan {
                fx_px: 457.587,
                fy_px: 456.134,
                cx_px: 379.999,
                cy_px: 255.238,
                k: [-0.28368365, 0.07451284],
                p: [-0.00010473, -3.55590700e-05],
            },
        )
    }

    fn rot_y(a: f64) -> Matrix3<f64> {
        Matrix3::new(a.cos(), 0.0, a.sin(), 0.0, 1.0, 0.0, -a.sin(), 0.0, a.cos())
    }

    fn ideal(f: f64, cx: f64, cy: f64) -> PinholeRadtan {
        PinholeRadtan { fx_px: f, fy_px: f, cx_px: cx, cy_px: cy, k: [0.0; 2], p: [0.0; 2] }
    }

    /// `X₁ = R X₀ + t` from two camera-to-body transforms.
    fn relative(b0: &[f64; 16], b1: &[f64; 16]) -> (Matrix3<f64>, Vector3<f64>) {
        let t = Matrix4::from_row_slice(b1).try_inverse().unwrap() * Matrix4::from_row_slice(b0);
        (t.fixed_view::<3, 3>(0, 0).into_owned(), t.fixed_view::<3, 1>(0, 3).into_owned())
    }

    #[test]
    fn undistort_inverts_distort() {
        let (c0, c1) = euroc_cams();
        for cam in [c0, c1] {
            for i in 0..=20 {
                for j in 0..=20 {
                    let (x, y) = (-0.9 + 0.09 * f64::from(i), -0.6 + 0.06 * f64::from(j));
                    let (xd, yd) = cam.distort(x, y);
                    let (xu, yu) = cam.undistort(xd, yd).unwrap();
                    assert!((xu - x).abs() < 1e-11 && (yu - y).abs() < 1e-11, "{x} {y}");
                }
            }
            // Every pixel of the 752x480 image has an undistorted ray that distorts back.
            for (u, v) in [(0.0, 0.0), (751.0, 479.0), (0.0, 479.0), (400.0, 10.0)] {
                let ray = cam.undistort_pixel(u, v).unwrap();
                let (xd, yd) = cam.distort(ray.x, ray.y);
                let (pu, pv) = (cam.fx_px * xd + cam.cx_px, cam.fy_px * yd + cam.cy_px);
                assert!((pu - u).abs() < 1e-8 && (pv - v).abs() < 1e-8);
            }
        }
        // Tangential terms alone (a case the radial factor does not cover).
        let cam = PinholeRadtan { k: [0.0; 2], p: [0.01, -0.02], ..ideal(400.0, 320.0, 240.0) };
        let (xd, yd) = cam.distort(0.3, -0.2);
        let (x, y) = cam.undistort(xd, yd).unwrap();
        assert!((x - 0.3).abs() < 1e-12 && (y + 0.2).abs() < 1e-12);
    }

    /// Converging cameras turned ±θ/2 about y, a baseline along x after the half turns, no
    /// distortion: R₀ = R_y(θ/2), R₁ = R_y(−θ/2), f = fy, and the principal point from the four
    /// rotated corners, worked out by hand below.
    #[test]
    fn converging_pair_matches_the_hand_computed_rectification() {
        let (theta, b, f, cx, cy, w, h) = (0.1_f64, 0.2, 500.0, 300.0, 200.0, 640_u32, 480_u32);
        let cam = ideal(f, cx, cy);
        // X₁ = R_y(−θ) X₀ + t: the half turn is R_y(θ/2), and t = R_y(−θ/2)·(−b, 0, 0) puts
        // the turned baseline on −x, so no further turn W is needed.
        let r = rot_y(-theta);
        let t = rot_y(-theta / 2.0) * Vector3::new(-b, 0.0, 0.0);
        let rect = stereo_rectify(&cam, &cam, &r, &t, (w, h), None).unwrap();
        assert!((rect.r_left - rot_y(-theta / 2.0)).amax() < 1e-14, "{}", rect.r_left);
        assert!((rect.r_right - rot_y(theta / 2.0)).amax() < 1e-14, "{}", rect.r_right);
        assert_eq!(rect.calib.fx_px, f);
        assert_eq!(rect.calib.fy_px, f);
        assert!((rect.calib.baseline_m - b).abs() < 1e-15);
        // Corner (u, v) → (x, y) = ((u−cx)/f, (v−cy)/f); R_y(φ)(x, y, 1) projected with f:
        // f (x cos φ + sin φ) / (cos φ − x sin φ), f y / (cos φ − x sin φ).
        let mut c = (0.0, 0.0);
        for phi in [theta / 2.0, -theta / 2.0] {
            let (mut mx, mut my) = (0.0, 0.0);
            for (u, v) in [(0.0, 0.0), (639.0, 0.0), (0.0, 479.0), (639.0, 479.0)] {
                let (x, y) = ((u - cx) / f, (v - cy) / f);
                let d = phi.cos() - x * phi.sin();
                mx += f * (x * phi.cos() + phi.sin()) / d / 4.0;
                my += f * y / d / 4.0;
            }
            c.0 += (319.5 - mx) / 2.0;
            c.1 += (239.5 - my) / 2.0;
        }
        assert!((rect.calib.cx_px - c.0).abs() < 1e-9, "{} vs {}", rect.calib.cx_px, c.0);
        assert!((rect.calib.cy_px - c.1).abs() < 1e-9, "{} vs {}", rect.calib.cy_px, c.1);
        // The numbers themselves, for a reader: (cx, cy) ≈ (300.0, 200.0) moved by the turn.
        assert!((c.0 - 300.0).abs() < 2.0 && (c.1 - 200.0).abs() < 1.0, "{c:?}");
    }

    /// A general rig (EuRoC's calibration): a 3D point seen by both cameras lands on the same
    /// rectified row, at disparity f·b/Z.
    #[test]
    fn rectified_points_share_rows_and_have_stereo_disparity() {
        let (c0, c1) = euroc_cams();
        let (r, t) = relative(&EUROC_T_BS0, &EUROC_T_BS1);
        let rect = stereo_rectify(&c0, &c1, &r, &t, (752, 480), Some(0.0)).unwrap();
        let k = rect.calib;
        for (i, p0) in [
            Vector3::new(0.3, -0.2, 2.0),
            Vector3::new(-1.0, 0.5, 4.0),
            Vector3::new(0.0, 0.0, 10.0),
            Vector3::new(2.0, 1.0, 6.0),
        ]
        .iter()
        .enumerate()
        {
            let p1 = r * p0 + t;
            let seen = |cam: &PinholeRadtan, p: &Vector3<f64>, rot: &Matrix3<f64>| {
                let (xd, yd) = cam.distort(p.x / p.z, p.y / p.z);
                let (u, v) = (cam.fx_px * xd + cam.cx_px, cam.fy_px * yd + cam.cy_px);
                let ray = rot * cam.undistort_pixel(u, v).unwrap();
                (k.fx_px * ray.x / ray.z + k.cx_px, k.fy_px * ray.y / ray.z + k.cy_px)
            };
            let (ul, vl) = seen(&c0, p0, &rect.r_left);
            let (ur, vr) = seen(&c1, &p1, &rect.r_right);
            let z = (rect.r_left * p0).z;
            assert!((vl - vr).abs() < 1e-8, "point {i}: rows {vl} {vr}");
            assert!(((ul - ur) - k.fx_px * k.baseline_m / z).abs() < 1e-8, "point {i}");
        }
    }

    /// The EuRoC pair. The rectifying rotations and the baseline agree to rounding with
    /// ORB-SLAM2's `Examples/Stereo/EuRoC.yaml` (LEFT.R, RIGHT.R, RIGHT.P of OpenCV's
    /// `stereoRectify`). Its rectified camera (f 435.205, c (367.452, 252.201) px) is not the
    /// one the published algorithm gives for `sensor.yaml` (with 5 or with converged
    /// undistortion steps, any alpha): the f and c below were computed with an independent
    /// plain-Python transcription of OpenCV's `cvStereoRectify` (alpha = 0, converged
    /// undistortion). Any shared rectified camera is a valid rectification; this one is
    /// OpenCV's rule.
    #[test]
    fn euroc_rectification_matches_opencv() {
        let (c0, c1) = euroc_cams();
        let (r, t) = relative(&EUROC_T_BS0, &EUROC_T_BS1);
        let rect = stereo_rectify(&c0, &c1, &r, &t, (752, 480), Some(0.0)).unwrap();
        let left_r = Matrix3::new(
            0.999966347530033,
            -0.001422739138722922,
            0.008079580483432283,
            0.001365741834644127,
            0.9999741760894847,
            0.007055629199258132,
            -0.008089410156878961,
            -0.007044357138835809,
            0.9999424675829176,
        );
        let right_r = Matrix3::new(
            0.9999633526194376,
            -0.003625811871560086,
            0.007755443660172947,
            0.003680398547259526,
            0.9999684752771629,
            -0.007035845251224894,
            -0.007729688520722713,
            0.007064130529506649,
            0.999945173484644,
        );
        assert!((rect.r_left - left_r).amax() < 1e-9, "{}", rect.r_left);
        assert!((rect.r_right - right_r).amax() < 1e-9, "{}", rect.r_right);
        let c = rect.calib;
        // ORB-SLAM2: bf = 47.90639384423901 px·m at f = 435.2046959714599 px.
        assert!((c.baseline_m - 47.90639384423901 / 435.2046959714599).abs() < 1e-9, "{c:?}");
        assert!((c.fx_px - 436.2114578882548).abs() < 1e-6 && c.fy_px == c.fx_px, "{c:?}");
        assert!((c.cx_px - 364.44525599428067).abs() < 1e-6, "{c:?}");
        assert!((c.cy_px - 256.9426848738351).abs() < 1e-6, "{c:?}");
    }

    /// alpha = 0 keeps only pixels seen by both source images; alpha = 1 keeps every source
    /// pixel, so black (unseen) pixels appear.
    #[test]
    fn alpha_zero_has_no_unseen_pixels() {
        let (c0, c1) = euroc_cams();
        let (r, t) = relative(&EUROC_T_BS0, &EUROC_T_BS1);
        let size = (752, 480);
        let inside = |alpha: f64| {
            let rect = stereo_rectify(&c0, &c1, &r, &t, size, Some(alpha)).unwrap();
            let m = StereoRemap::new(&c0, &c1, &rect, size);
            let mut n = 0usize;
            for table in [&m.left, &m.right] {
                for v in 0..size.1 {
                    for u in 0..size.0 {
                        let (x, y) = table.source(u, v).unwrap();
                        n += usize::from(x >= -0.5 && y >= -0.5 && x <= 751.5 && y <= 479.5);
                    }
                }
            }
            n as f64 / (2.0 * 752.0 * 480.0)
        };
        let (zero, one) = (inside(0.0), inside(1.0));
        assert!(zero > 0.9995, "{zero}");
        assert!(one < 0.99, "{one}");
    }

    /// Identical undistorted cameras side by side: the rectified camera is theirs and the
    /// remap leaves images unchanged, bit for bit.
    #[test]
    fn identity_rig_gives_an_identity_remap() {
        let cam = ideal(420.0, 161.5, 99.25);
        let size = (320, 200);
        let rect = stereo_rectify(
            &cam,
            &cam,
            &Matrix3::identity(),
            &Vector3::new(-0.12, 0.0, 0.0),
            size,
            Some(0.0),
        )
        .unwrap();
        assert_eq!(rect.r_left, Matrix3::identity());
        assert_eq!(rect.r_right, Matrix3::identity());
        let c = rect.calib;
        assert!((c.fx_px - 420.0).abs() < 1e-9 && (c.fy_px - 420.0).abs() < 1e-9, "{c:?}");
        assert!((c.cx_px - 161.5).abs() < 1e-9 && (c.cy_px - 99.25).abs() < 1e-9, "{c:?}");
        assert!((c.baseline_m - 0.12).abs() < 1e-15);
        let m = StereoRemap::new(&cam, &cam, &rect, size);
        let img = GrayImage::from_fn(size.0, size.1, |x, y| {
            image::Luma([((x * 7 + y * 13 + (x * y) % 11) % 256) as u8])
        });
        assert_eq!(m.left.apply(&img), img);
        assert_eq!(m.right.apply(&img), img);
    }

    #[test]
    fn bilinear_sampling_interpolates_and_blacks_out_the_outside() {
        let src = GrayImage::from_raw(2, 2, vec![0, 100, 200, 50]).unwrap();
        let table =
            RemapTable { width: 3, height: 1, map: vec![[0.5, 0.5], [0.25, 0.0], [5.0, 0.0]] };
        let out = table.apply(&src);
        assert_eq!(out.as_raw(), &vec![88, 25, 0]); // (0+100+200+50)/4 = 87.5 → 88
    }

    #[test]
    fn unusable_rigs_are_refused() {
        let cam = ideal(400.0, 320.0, 240.0);
        let i = Matrix3::identity();
        let e = stereo_rectify(&cam, &cam, &i, &Vector3::zeros(), (640, 480), None).unwrap_err();
        assert!(e.contains("baseline"), "{e}");
        let e = stereo_rectify(&cam, &cam, &i, &Vector3::new(0.0, -0.1, 0.0), (640, 480), None)
            .unwrap_err();
        assert!(e.contains("vertically"), "{e}");
        let e = stereo_rectify(&cam, &cam, &i, &Vector3::new(0.1, 0.0, 0.0), (640, 480), None)
            .unwrap_err();
        assert!(e.contains("left of camera 0"), "{e}");
        // Distortion that folds over before the image border cannot be inverted there.
        let bad = PinholeRadtan { k: [-5.0, 0.0], ..cam };
        let e = stereo_rectify(&bad, &bad, &i, &Vector3::new(-0.1, 0.0, 0.0), (640, 480), None)
            .unwrap_err();
        assert!(e.contains("cannot be inverted"), "{e}");
    }
}
