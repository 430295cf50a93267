//! The `.slm` model blob from untrusted bytes: `Model::parse` must answer every input with
//! `Ok` or a typed error, never a panic; a blob it accepts must run through the executor
//! without error, with the reference and fast kernels bit-equal (the parser's promise: "a
//! blob that parses cannot make the executor fail").
//!
//! The first input byte is a flag set, the rest the blob. Bit 0 writes the input's length
//! into the header's `total_len` and bit 1 re-seals the CRC-32, so mutations reach the
//! structural checks behind the checksum instead of all failing at it.
#![no_main]

use libfuzzer_sys::fuzz_target;
use semloc_core::nn::graph::{run, Kernels};
use semloc_core::nn::model::{crc32, Model, HEADER_LEN};

/// Keeps one run cheap: graphs bigger than this are parsed and validated but not executed.
const MAX_ARENA: usize = 4 << 20;
const MAX_MACS: u64 = 20_000_000;

fuzz_target!(|data: &[u8]| {
    let Some((&flags, body)) = data.split_first() else { return };
    // 4-byte aligned copy, as the parser requires (`Misaligned` otherwise).
    let mut words = vec![0u32; body.len().div_ceil(4)];
    let bytes = &mut bytemuck::cast_slice_mut::<u32, u8>(&mut words)[..body.len()];
    bytes.copy_from_slice(body);
    if bytes.len() >= HEADER_LEN {
        if flags & 1 != 0 {
            let n = bytes.len() as u32;
            bytes[12..16].copy_from_slice(&n.to_le_bytes());
        }
        if flags & 2 != 0 {
            let total = (u32::from_le_bytes([bytes[12], bytes[13], bytes[14], bytes[15]]) as usize)
                .min(bytes.len())
                .max(20);
            let c = crc32(&bytes[20..total]);
            bytes[16..20].copy_from_slice(&c.to_le_bytes());
        }
    }
    let blob: &[u8] = bytes;
    let Ok(model) = Model::parse(blob) else { return };
    // The cached layout must give back the same model.
    let layout = model.layout();
    let again = Model::attach(&layout, blob).expect("attach of a parsed blob");
    assert_eq!(again.n_ops(), model.n_ops());
    if model.arena_len() > MAX_ARENA {
        return;
    }
    let mut macs = 0u64;
    for k in 0..model.n_ops() {
        let op = model.op(k);
        let (ins, _) = op.inputs();
        let (Some(i), Some(o)) =
            (model.tensor(ins[0] as usize), model.tensor(op.output() as usize))
        else {
            panic!("a parsed op names a missing tensor");
        };
        macs += op.macs(i.shape, o.shape);
    }
    if macs > MAX_MACS {
        return;
    }
    let (h, w) = model.input_size();
    let input: Vec<u8> = (0..h * w).map(|i| (i * 31 + usize::from(flags)) as u8).collect();
    let mut a1 = vec![0i8; model.arena_len()];
    let mut a2 = vec![0i8; model.arena_len()];
    let fast = run(&model, &input, &mut a1, Kernels::Fast).expect("a parsed blob runs").to_vec();
    let reference = run(&model, &input, &mut a2, Kernels::Reference).expect("reference run");
    assert_eq!(fast, reference, "fast and reference kernels differ");
});
