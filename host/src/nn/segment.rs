//! Frame → labels with the int8 engine (and the float reference on the same input map).
//!
//! [`Segmenter`] owns a loaded `.slm` blob, its activation arena and the input/label buffers,
//! and runs one frame as the pipeline and firmware do ([`graph::segment_frame`]):
//! [`Letterbox::fit`] the frame to the network input (integer box down-scaling, edge padding),
//! [`prepare_input`], the core executor ([`graph::run`]), [`graph::argmax`],
//! [`labels_to_frame`] (nearest). The float reference
//! ([`TractRef`]) is run on the *same* prepared input map, so the two differ only by the
//! network arithmetic. [`overlay`] draws labels over the frame in the CamVid palette.
//!
//! Memory: the arena ([`Model::arena_len`], ≈ 2 MB at 192x640), the input map and two label
//! maps; allocated once per [`Segmenter`].

use image::{GrayImage, RgbImage};
use semloc_core::nn::graph::{
    self, labels_to_frame, prepare_input, Kernels, Letterbox, SegBuffers,
};
use semloc_core::nn::model::Model;

use super::tract_ref::TractRef;
use super::{NnFileError, SlmBlob};

/// The SegNet CamVid palette (RGB) by class id; id 11 (void) and unknown ids are black.
pub const CAMVID_PALETTE: [[u8; 3]; 12] = [
    [128, 128, 128], // sky
    [128, 0, 0],     // building
    [192, 192, 128], // pole
    [128, 64, 128],  // road
    [60, 40, 222],   // pavement
    [128, 128, 0],   // tree
    [192, 128, 128], // sign-symbol
    [64, 64, 128],   // fence
    [64, 0, 128],    // car
    [64, 64, 0],     // pedestrian
    [0, 128, 192],   // bicyclist
    [0, 0, 0],       // void
];

/// The int8 engine with its buffers.
pub struct Segmenter {
    blob: SlmBlob,
    arena: Vec<i8>,
    input: Vec<u8>,
    labels: Vec<u8>,
    hw: (usize, usize),
}

/// One frame's result.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FrameLabels {
    /// Labels on the network's output map (`model_h x model_w`).
    pub model: Vec<u8>,
    /// Labels on the frame (`src_w x src_h`, row-major).
    pub frame: Vec<u8>,
}

impl Segmenter {
    /// Buffers for `blob`. The model's output must be at the input's resolution (the
    /// full-resolution export; a 1/8 export is an error here).
    pub fn new(blob: SlmBlob) -> Result<Self, NnFileError> {
        let m = blob.model()?;
        let hw = m.input_size();
        let o = m.output_shape();
        if (o.h, o.w) != hw {
            return Err(NnFileError::Tensor {
                path: blob.path().to_path_buf(),
                tensor: "output".into(),
                msg: format!(
                    "output {}x{} is not at the input's {}x{} (export with the final upsample)",
                    o.h, o.w, hw.0, hw.1
                ),
            });
        }
        let arena = vec![0i8; m.arena_len()];
        let n = hw.0 * hw.1;
        Ok(Segmenter { blob, arena, input: vec![0; n], labels: vec![0; n], hw })
    }

    /// The model.
    pub fn model(&self) -> Result<Model<'_>, NnFileError> {
        self.blob.model()
    }

    /// The network input `(h, w)`.
    pub fn input_size(&self) -> (usize, usize) {
        self.hw
    }

    /// Bytes of network memory: the blob (weights, read in place), the activation arena and
    /// the input and label maps.
    pub fn memory_bytes(&self) -> usize {
        self.blob.bytes().len() + self.arena.len() + self.input.len() + self.labels.len()
    }

    /// The blob.
    pub fn blob(&self) -> &SlmBlob {
        &self.blob
    }

    /// How a `w x h` frame maps onto the network input.
    pub fn letterbox(&self, w: usize, h: usize) -> Result<Letterbox, NnFileError> {
        Letterbox::fit(w, h, self.hw.0, self.hw.1).map_err(|e| self.err(e))
    }

    /// Fills the network input map from a frame (kept for [`Segmenter::run_prepared`] and the
    /// float reference) and returns it.
    pub fn prepare(&mut self, frame: &GrayImage) -> Result<(Letterbox, &[u8]), NnFileError> {
        let lb = self.letterbox(frame.width() as usize, frame.height() as usize)?;
        prepare_input(frame.as_raw(), &lb, &mut self.input).map_err(|e| self.err(e))?;
        Ok((lb, &self.input))
    }

    /// Runs the int8 network on the input map filled by [`Segmenter::prepare`]; returns the
    /// labels on the model map.
    pub fn run_prepared(&mut self, kernels: Kernels) -> Result<&[u8], NnFileError> {
        self.run_prepared_observed(kernels, &mut |_| {})
    }

    /// [`Segmenter::run_prepared`], calling `after_op(k)` when op `k` has finished (per-op
    /// profiling).
    pub fn run_prepared_observed(
        &mut self,
        kernels: Kernels,
        after_op: &mut dyn FnMut(usize),
    ) -> Result<&[u8], NnFileError> {
        let m = self.blob.model()?;
        let out = graph::run_observed(&m, &self.input, &mut self.arena, kernels, after_op)
            .map_err(|e| NnFileError::model(self.blob.path(), e))?;
        graph::argmax(out, m.output_shape(), &mut self.labels)
            .map_err(|e| NnFileError::model(self.blob.path(), e))?;
        Ok(&self.labels)
    }

    /// Runs the fast and the reference kernels on the current input map and counts the output
    /// logits that differ (0: bit-identical, as the core promises).
    pub fn compare_kernels(&mut self) -> Result<usize, NnFileError> {
        let m = self.blob.model()?;
        let path = self.blob.path();
        let fast = graph::run(&m, &self.input, &mut self.arena, Kernels::Fast)
            .map_err(|e| NnFileError::model(path, e))?
            .to_vec();
        let reference = graph::run(&m, &self.input, &mut self.arena, Kernels::Reference)
            .map_err(|e| NnFileError::model(path, e))?;
        Ok(fast.iter().zip(reference).filter(|(a, b)| a != b).count())
    }

    /// The whole frame path, as the pipeline and firmware run it ([`graph::segment_frame`]):
    /// letterbox, int8 network, argmax, labels back on the frame. Leaves the input map in place
    /// for [`Segmenter::reference`] and [`Segmenter::compare_kernels`].
    pub fn segment(
        &mut self,
        frame: &GrayImage,
        kernels: Kernels,
    ) -> Result<FrameLabels, NnFileError> {
        let lb = self.letterbox(frame.width() as usize, frame.height() as usize)?;
        let m = self.blob.model()?;
        let mut out = vec![0u8; lb.src_w * lb.src_h];
        let bufs =
            SegBuffers { input: &mut self.input, arena: &mut self.arena, labels: &mut self.labels };
        graph::segment_frame(&m, &lb, frame.as_raw(), bufs, kernels, &mut out)
            .map_err(|e| NnFileError::model(self.blob.path(), e))?;
        Ok(FrameLabels { model: self.labels.clone(), frame: out })
    }

    /// The float reference on the current input map (call [`Segmenter::prepare`] first):
    /// labels on the model map.
    pub fn reference(&self, tract: &TractRef) -> Result<Vec<u8>, NnFileError> {
        if tract.input_size() != self.hw {
            return Err(NnFileError::Tract {
                path: self.blob.path().to_path_buf(),
                msg: format!(
                    "the ONNX takes {:?}, the blob {:?}: not the same export",
                    tract.input_size(),
                    self.hw
                ),
            });
        }
        let logits = tract.run(&self.input)?;
        let mut l = vec![0u8; self.hw.0 * self.hw.1];
        logits.argmax(&mut l);
        Ok(l)
    }

    fn err(&self, e: semloc_core::nn::model::ModelError) -> NnFileError {
        NnFileError::model(self.blob.path(), e)
    }
}

/// Model-map labels back on the frame (nearest).
pub fn to_frame(
    model_labels: &[u8],
    lb: &Letterbox,
) -> Result<Vec<u8>, semloc_core::nn::model::ModelError> {
    let mut out = vec![0u8; lb.src_w * lb.src_h];
    labels_to_frame(model_labels, lb, &mut out)?;
    Ok(out)
}

/// Labels as a grey image of class ids.
pub fn label_image(labels: &[u8], w: u32, h: u32) -> GrayImage {
    GrayImage::from_fn(w, h, |x, y| image::Luma([labels[(y * w + x) as usize]]))
}

/// The labels in the CamVid palette blended 50 % over the (grey) frame.
pub fn overlay(frame: &GrayImage, labels: &[u8]) -> RgbImage {
    let w = frame.width();
    RgbImage::from_fn(w, frame.height(), |x, y| {
        let g = u16::from(frame.get_pixel(x, y)[0]);
        let id = labels.get((y * w + x) as usize).copied().unwrap_or(11) as usize;
        let c = CAMVID_PALETTE[id.min(11)];
        image::Rgb(c.map(|v| (u16::from(v) + g).div_ceil(2) as u8))
    })
}

/// [`overlay`] with a legend band below it: one swatch in the palette colour and the class
/// name per CamVid class (and void), wrapped to the image width.
pub fn overlay_with_legend(frame: &GrayImage, labels: &[u8]) -> RgbImage {
    const ROW: u32 = 14;
    let names = semloc_core::seg::CLASS_NAMES.iter().copied().chain(core::iter::once("void"));
    let w = frame.width();
    // Lay the entries out first to know how many rows the band needs.
    let mut pos = Vec::new();
    let (mut x, mut row) = (4u32, 0u32);
    for (id, name) in names.enumerate() {
        let width = 14 + 8 * name.len() as u32 + 10;
        if x + width > w && x > 4 {
            x = 4;
            row += 1;
        }
        pos.push((id, name, x, row));
        x += width;
    }
    let band = (row + 1) * ROW + 4;
    let top = overlay(frame, labels);
    let mut out = RgbImage::from_pixel(w, frame.height() + band, image::Rgb([255, 255, 255]));
    image::imageops::replace(&mut out, &top, 0, 0);
    for (id, name, x, row) in pos {
        let y = frame.height() + 3 + row * ROW;
        let c = CAMVID_PALETTE[id];
        for dy in 0..10 {
            for dx in 0..10 {
                if x + dx < w {
                    out.put_pixel(x + dx, y + dy, image::Rgb(c));
                }
            }
        }
        crate::plot::draw_label(&mut out, x as i32 + 14, y as i32, name, 12, [0, 0, 0]);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::super::convert::convert;
    use super::super::fixtures::{test_images, tiny_onnx, tiny_quant};
    use super::super::onnx::OnnxGraph;
    use super::*;
    use prost::Message;
    use std::path::Path;

    /// A pipeline given the network tells the tracker its labels are the network's, so EM
    /// leaves out the class term by default (`tracker.em.class_term = "not-network"`).
    #[test]
    fn a_pipeline_with_a_network_says_its_labels_are_the_networks() {
        let bytes = tiny_onnx(24, 32).encode_to_vec();
        let g = OnnxGraph::from_bytes(&bytes, Path::new("tiny.onnx")).unwrap();
        let q = tiny_quant(&bytes).unwrap();
        let blob = convert(&g, &q, Path::new("q.json")).unwrap().encode().unwrap();
        let calib = crate::dataset::StereoCalib {
            fx_px: 50.0,
            fy_px: 50.0,
            cx_px: 32.0,
            cy_px: 24.0,
            baseline_m: 0.5,
        };
        let params = semloc_core::tracker::TrackerParams::default();
        let mut pipe = crate::pipeline::Pipeline::new(&calib, 64, 48, params, 1).unwrap();
        assert!(!pipe.tracker().network_labels());
        pipe.set_segmenter(Segmenter::new(blob).unwrap());
        assert!(pipe.tracker().network_labels());
    }

    /// Converter round trip: the tiny net in tract (f32) and converted to int8 in the core
    /// label a frame alike, and the fast and reference kernels agree bit for bit.
    #[test]
    fn int8_follows_the_float_reference_on_the_tiny_net() {
        let bytes = tiny_onnx(24, 32).encode_to_vec();
        let path = Path::new("tiny.onnx");
        let g = OnnxGraph::from_bytes(&bytes, path).unwrap();
        let q = tiny_quant(&bytes).unwrap();
        let blob = convert(&g, &q, Path::new("q.json")).unwrap().encode().unwrap();
        let mut seg = Segmenter::new(blob).unwrap();
        let tract = TractRef::from_bytes(&bytes, path).unwrap();
        let (mut same, mut total) = (0, 0);
        // images of the calibration family not calibrated on, upscaled x2 (64x48 frames: the
        // letterbox's 2x2 box mean gives the 24x32 image back)
        for img in &test_images(24, 32, 12)[8..] {
            let frame = GrayImage::from_fn(64, 48, |x, y| {
                image::Luma([img[(y as usize / 2) * 32 + x as usize / 2]])
            });
            let labels = seg.segment(&frame, Kernels::Fast).unwrap();
            assert_eq!(labels.frame.len(), 64 * 48);
            assert_eq!(seg.compare_kernels().unwrap(), 0);
            let f = seg.reference(&tract).unwrap();
            same += labels.model.iter().zip(&f).filter(|(a, b)| a == b).count();
            total += f.len();
        }
        let agree = same as f64 / total as f64;
        assert!(agree > 0.97, "int8 vs f32 label agreement {agree}");
    }

    #[test]
    fn legend_names_every_class_below_the_overlay() {
        let frame = GrayImage::from_pixel(300, 20, image::Luma([100]));
        let labels = vec![8u8; 300 * 20];
        let img = overlay_with_legend(&frame, &labels);
        assert_eq!(img.width(), 300);
        // 12 entries do not fit one 300 px row: the band wraps into several 14 px rows.
        assert!(img.height() >= 20 + 3 * 14, "height {}", img.height());
        assert_eq!(img.get_pixel(5, 5), &overlay(&frame, &labels).get_pixel(5, 5).clone());
        // The first swatch is the sky colour.
        assert_eq!(img.get_pixel(6, 25).0, CAMVID_PALETTE[0]);
    }

    #[test]
    fn overlay_blends_half_and_half() {
        let f = GrayImage::from_pixel(2, 1, image::Luma([100]));
        let o = overlay(&f, &[3, 11]);
        assert_eq!(o.get_pixel(0, 0).0, [114, 82, 114]);
        assert_eq!(o.get_pixel(1, 0).0, [50, 50, 50]);
        let l = label_image(&[1, 2], 2, 1);
        assert_eq!(l.as_raw(), &vec![1, 2]);
    }
}
