//! The float reference: the same ONNX the int8 blob was converted from, run by tract.
//!
//! tract-onnx loads the float export (`models/export.py`: BN folded, opset 17), optimises it
//! and runs it in `f32` on one thread (tract's default executor is single-threaded), with the
//! input the network was trained on: `luma / 255` as a `1 x 1 x H x W` tensor. The logits come
//! back NCHW; [`argmax_nchw`] turns them into labels with ties going to the lowest class (as
//! the core's `argmax`).
//!
//! This is a float reference, not a fake-quant one: there is no QDQ ONNX of the network
//! (`quantise.py` writes a JSON sidecar, not Q/DQ nodes), so the int8-vs-float gap measured
//! against it is the whole quantisation error, which is what matters for the labels.
//!
//! Memory: tract's optimised model (≈ the f32 weights) plus one logits tensor per run.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use tract_onnx::prelude::*;

use super::NnFileError;

/// A loaded, optimised float model.
#[derive(Debug, Clone)]
pub struct TractRef {
    path: PathBuf,
    plan: Arc<TypedRunnableModel>,
    h: usize,
    w: usize,
}

/// Float logits, NCHW with N = 1.
#[derive(Debug, Clone, PartialEq)]
pub struct Logits {
    /// Classes.
    pub c: usize,
    /// Height.
    pub h: usize,
    /// Width.
    pub w: usize,
    /// `c·h·w` values, channel-major.
    pub data: Vec<f32>,
}

impl Logits {
    /// Per-pixel argmax into `labels` (`h·w`), ties to the lowest class.
    pub fn argmax(&self, labels: &mut [u8]) {
        argmax_nchw(&self.data, self.c, self.h * self.w, labels);
    }
}

/// Argmax over `c` planes of `n` values each; ties to the lowest class. Writes `min(n, labels)`
/// labels.
pub fn argmax_nchw(data: &[f32], c: usize, n: usize, labels: &mut [u8]) {
    for (p, l) in labels.iter_mut().enumerate().take(n) {
        let mut best = 0usize;
        let mut v = f32::NEG_INFINITY;
        for k in 0..c {
            let x = data.get(k * n + p).copied().unwrap_or(f32::NEG_INFINITY);
            if x > v {
                v = x;
                best = k;
            }
        }
        *l = best.min(255) as u8;
    }
}

impl TractRef {
    /// Loads and optimises an ONNX file.
    pub fn load(path: &Path) -> Result<Self, NnFileError> {
        if !path.is_file() {
            return Err(NnFileError::Missing { path: path.to_path_buf() });
        }
        let model = tract_onnx::onnx().model_for_path(path).map_err(|e| tract_err(path, &e))?;
        Self::from_model(model, path)
    }

    /// Loads ONNX protobuf bytes (`path` is named in errors).
    pub fn from_bytes(bytes: &[u8], path: &Path) -> Result<Self, NnFileError> {
        let mut r = bytes;
        let model = tract_onnx::onnx().model_for_read(&mut r).map_err(|e| tract_err(path, &e))?;
        Self::from_model(model, path)
    }

    fn from_model(model: InferenceModel, path: &Path) -> Result<Self, NnFileError> {
        let typed = model
            .into_optimized()
            .and_then(|m| {
                let shape = m.input_fact(0)?.shape.as_concrete().map(<[usize]>::to_vec);
                Ok((m, shape))
            })
            .map_err(|e| tract_err(path, &e))?;
        let (m, shape) = typed;
        let (h, w) = match shape.as_deref() {
            Some(&[1, 1, h, w]) => (h, w),
            other => {
                return Err(NnFileError::Tract {
                    path: path.to_path_buf(),
                    msg: format!("input shape {other:?}, expected static 1 x 1 x H x W"),
                })
            }
        };
        let plan = m.into_runnable().map_err(|e| tract_err(path, &e))?;
        Ok(TractRef { path: path.to_path_buf(), plan, h, w })
    }

    /// The input map `(h, w)`.
    pub fn input_size(&self) -> (usize, usize) {
        (self.h, self.w)
    }

    /// Runs the model on an `h x w` luma map (row-major).
    pub fn run(&self, luma: &[u8]) -> Result<Logits, NnFileError> {
        let n = self.h * self.w;
        if luma.len() != n {
            return Err(NnFileError::Tract {
                path: self.path.clone(),
                msg: format!(
                    "input has {} pixels, the model takes {}x{}",
                    luma.len(),
                    self.h,
                    self.w
                ),
            });
        }
        let x: Vec<f32> = luma.iter().map(|&v| f32::from(v) / 255.0).collect();
        let run = || -> TractResult<Logits> {
            let t = Tensor::from_shape(&[1, 1, self.h, self.w], &x)?;
            let out = self.plan.run(tvec!(t.into()))?;
            let y = out[0].to_plain_array_view::<f32>()?;
            let s = y.shape().to_vec();
            let [1, c, h, w] = s[..] else {
                anyhow::bail!("output shape {s:?}, expected 1 x C x H x W");
            };
            Ok(Logits { c, h, w, data: y.iter().copied().collect() })
        };
        run().map_err(|e| tract_err(&self.path, &e))
    }
}

fn tract_err(path: &Path, e: &TractError) -> NnFileError {
    NnFileError::Tract { path: path.to_path_buf(), msg: format!("{e:#}") }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn argmax_ties_go_to_the_lowest_class() {
        // 3 classes, 2 pixels
        let d = [1.0, 5.0, 2.0, 5.0, 2.0, -1.0];
        let mut l = [9u8; 2];
        argmax_nchw(&d, 3, 2, &mut l);
        assert_eq!(l, [1, 0]);
    }

    #[test]
    fn missing_and_bad_files_name_the_file() {
        let e = TractRef::load(Path::new("/nonexistent/m.onnx")).unwrap_err();
        assert_eq!(e.to_string(), "/nonexistent/m.onnx: missing file");
        let e = TractRef::from_bytes(b"\x08\x01junk", Path::new("j.onnx")).unwrap_err();
        assert!(e.to_string().starts_with("j.onnx: tract:"), "{e}");
    }
}
