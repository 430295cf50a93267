//! The one error type of the host network code: every variant names the file it is about and,
//! where there is one, the ONNX node or tensor, so a message alone says what to fix.

use std::path::{Path, PathBuf};

use semloc_core::nn::model::ModelError;

/// Why a network file (ONNX, `quant.json`, `.slm`) could not be read, converted or run.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum NnFileError {
    /// The file does not exist.
    #[error("{}: missing file", path.display())]
    Missing {
        /// The path looked for.
        path: PathBuf,
    },
    /// The file exists but could not be read or written.
    #[error("{}: cannot read or write: {msg}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The operating system's reason.
        msg: String,
    },
    /// The file is not a decodable ONNX protobuf (or has no graph).
    #[error("{}: not a valid ONNX model: {msg}", path.display())]
    Decode {
        /// The ONNX file.
        path: PathBuf,
        /// The decoder's reason.
        msg: String,
    },
    /// A node the int8 engine cannot run, or whose attributes or inputs are invalid.
    #[error("{}: node `{node}` ({op}): {msg}", path.display())]
    Node {
        /// The ONNX file.
        path: PathBuf,
        /// Node name (or its first output when unnamed).
        node: String,
        /// ONNX op type.
        op: String,
        /// What is wrong.
        msg: String,
    },
    /// A tensor (initializer, graph input/output, activation) is missing or malformed.
    #[error("{}: tensor `{tensor}`: {msg}", path.display())]
    Tensor {
        /// The file (ONNX or quant.json) at fault.
        path: PathBuf,
        /// Tensor name.
        tensor: String,
        /// What is wrong.
        msg: String,
    },
    /// The quantisation sidecar is not valid JSON of the expected form.
    #[error("{}: bad quantisation JSON: {msg}", path.display())]
    QuantJson {
        /// The `quant.json` file.
        path: PathBuf,
        /// What is wrong.
        msg: String,
    },
    /// A `.slm` blob failed to parse (bad magic, CRC, ...) or to encode.
    #[error("{}: {source}", path.display())]
    Model {
        /// The `.slm` file (or the file being converted).
        path: PathBuf,
        /// The core's reason.
        source: ModelError,
    },
    /// tract could not load or run the float model.
    #[error("{}: tract: {msg}", path.display())]
    Tract {
        /// The ONNX file.
        path: PathBuf,
        /// tract's reason (with its context chain).
        msg: String,
    },
}

impl NnFileError {
    /// Maps an I/O error on `path` to `Missing` (not found) or `Io` (anything else).
    pub fn io(path: &Path, e: &std::io::Error) -> Self {
        if e.kind() == std::io::ErrorKind::NotFound {
            Self::Missing { path: path.to_path_buf() }
        } else {
            Self::Io { path: path.to_path_buf(), msg: e.to_string() }
        }
    }

    /// A core [`ModelError`] about `path`.
    pub fn model(path: &Path, source: ModelError) -> Self {
        Self::Model { path: path.to_path_buf(), source }
    }
}
