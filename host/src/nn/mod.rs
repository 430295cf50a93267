//! # nn (host): the segmentation network's files and float reference
//!
//! The std side of the int8 network (`semloc_core::nn`): reading the float ONNX export
//! ([`onnx`]), lowering it with `models/quantise.py`'s `quant.json` to the core's `.slm` blob
//! ([`convert`], `semloc convert`), loading a blob into aligned memory ([`SlmBlob`]), and running
//! the same float ONNX in tract as the reference the int8 engine is compared with
//! ([`tract_ref`], `semloc verify-seg`); [`segment`] runs frames through both, [`metrics`] scores
//! them as `models/camvid.py` does. Every error is an [`NnFileError`] naming the file and,
//! where there is one, the ONNX node or tensor.
//!
//! Memory: an `.slm` blob is held once (≈ 1.5 MB for the Res2Net net at 192x640) in a `Vec<u32>`
//! so the core can read it in place; the ONNX IR holds the float weights while converting.

pub mod convert;
mod error;
pub mod fixtures;
pub mod metrics;
pub mod onnx;
pub mod segment;
pub mod tract_ref;

use std::path::{Path, PathBuf};

use semloc_core::nn::model::{Model, ModelLayout};

pub use error::NnFileError;

/// An `.slm` blob in 4-byte-aligned memory (the core reads it in place), validated at load.
#[derive(Debug)]
pub struct SlmBlob {
    path: PathBuf,
    words: Vec<u32>,
    len: usize,
    /// Set by the one full parse at load; [`SlmBlob::model`] re-attaches it.
    layout: Option<ModelLayout>,
}

impl Clone for SlmBlob {
    /// A copy in new memory, parsed once again so [`SlmBlob::model`] stays cheap for it.
    fn clone(&self) -> Self {
        let mut b = SlmBlob {
            path: self.path.clone(),
            words: self.words.clone(),
            len: self.len,
            layout: None,
        };
        b.layout = Model::parse(b.bytes()).ok().map(|m| m.layout());
        b
    }
}

impl SlmBlob {
    /// Reads and validates an `.slm` file; errors name the file (a corrupt one: "CRC-32 ...").
    pub fn load(path: &Path) -> Result<Self, NnFileError> {
        let bytes = std::fs::read(path).map_err(|e| NnFileError::io(path, &e))?;
        Self::from_bytes(&bytes, path)
    }

    /// Copies `bytes` into aligned memory and validates them (`path` is named in errors).
    pub fn from_bytes(bytes: &[u8], path: &Path) -> Result<Self, NnFileError> {
        let mut words = vec![0u32; bytes.len().div_ceil(4)];
        bytemuck::cast_slice_mut::<u32, u8>(&mut words)[..bytes.len()].copy_from_slice(bytes);
        let mut blob = SlmBlob { path: path.to_path_buf(), words, len: bytes.len(), layout: None };
        let layout = Model::parse(blob.bytes()).map_err(|e| NnFileError::model(path, e))?.layout();
        blob.layout = Some(layout);
        Ok(blob)
    }

    /// The blob's bytes.
    pub fn bytes(&self) -> &[u8] {
        &bytemuck::cast_slice::<u32, u8>(&self.words)[..self.len]
    }

    /// The file it came from.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The parsed model (a view into this blob). Validated once at load; this re-attaches
    /// that parse (no CRC or validation per call), so it is cheap enough per frame.
    pub fn model(&self) -> Result<Model<'_>, NnFileError> {
        let r = match &self.layout {
            // a moved-from copy would not match; parse it then
            Some(l) => Model::attach(l, self.bytes()).or_else(|_| Model::parse(self.bytes())),
            None => Model::parse(self.bytes()),
        };
        r.map_err(|e| NnFileError::model(&self.path, e))
    }

    /// Writes the blob to `path`.
    pub fn save(&self, path: &Path) -> Result<(), NnFileError> {
        std::fs::write(path, self.bytes()).map_err(|e| NnFileError::io(path, &e))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn corrupt_and_short_blobs_are_errors_naming_the_file() {
        use prost::Message;
        let bytes = fixtures::tiny_onnx(8, 8).encode_to_vec();
        let g = onnx::OnnxGraph::from_bytes(&bytes, Path::new("t.onnx")).unwrap();
        let q = fixtures::tiny_quant(&bytes).unwrap();
        let blob = convert::convert(&g, &q, Path::new("t.quant.json")).unwrap().encode().unwrap();
        let mut b = blob.bytes().to_vec();
        let again = SlmBlob::from_bytes(&b, Path::new("m.slm")).unwrap();
        assert_eq!(again.bytes(), blob.bytes());
        let last = b.len() - 1;
        b[last] ^= 1;
        let e = SlmBlob::from_bytes(&b, Path::new("m.slm")).unwrap_err();
        assert!(e.to_string().starts_with("m.slm: model blob corrupt: CRC-32"), "{e}");
        let e = SlmBlob::from_bytes(&b[..40], Path::new("m.slm")).unwrap_err();
        assert!(e.to_string().starts_with("m.slm: model blob truncated"), "{e}");
        let e = SlmBlob::load(Path::new("/nonexistent/m.slm")).unwrap_err();
        assert_eq!(e.to_string(), "/nonexistent/m.slm: missing file");
    }
}
