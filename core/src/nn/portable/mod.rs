//! # portable: the safe fast kernels, one file per op family
//!
//! The fast kernels of every target, in safe Rust written for the compiler's auto-vectoriser
//! (contiguous row slices, hoisted bounds, `chunks_exact`, zipped loops), as tract's
//! `linalg/src/generic`. On x86-64 with AVX2 the `x86` kernels replace some of them (the
//! `dispatch` module decides); these remain the code of every other target (Cortex-M, aarch64)
//! and are tested on x86 too, bit-equal to the references.
//!
//! | file            | ONNX op                                      | stack            |
//! |-----------------|----------------------------------------------|------------------|
//! | [`conv`]        | `Conv`, `group = 1`, any kernel/stride/pads  | 5.8 KiB          |
//! | [`depthwise`]   | `Conv` depthwise 3×3, pad 1, stride 1/2      | 6.3 KiB          |
//! | [`pointwise`]   | `Conv` 1×1 (int8 GEMM over packed weights)   | 10 KiB           |
//! | [`resize`]      | `Resize` bilinear, `half_pixel`              | none             |
//! | [`eltwise`]     | `Add`, `Concat` (channels), `Relu`           | 2 KiB (`Add`)    |
//! | [`pool`]        | `AveragePool` (the PPM's)                    | 256 B            |
//!
//! **ISA:** none required. Each kernel takes the operands its op has checked
//! (`conv::pointwise_fast` etc.) and does not panic on them.

pub(crate) mod conv;
pub(crate) mod depthwise;
pub(crate) mod eltwise;
pub(crate) mod pointwise;
pub(crate) mod pool;
pub(crate) mod resize;
