//! `semloc convert`: a float ONNX export + its `quant.json` → the int8 `.slm` blob the core runs.

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;
use semloc::nn::convert::{convert_files, ModelSummary, QuantParams};

/// Arguments of `semloc convert`.
#[derive(Args, Debug)]
pub struct ConvertArgs {
    /// The float ONNX export (`models/export.py`).
    #[arg(long, value_name = "X.onnx")]
    pub onnx: PathBuf,
    /// Its quantisation sidecar (`models/quantise.py`); default: `X.quant.json` beside the ONNX.
    #[arg(long, value_name = "X.quant.json")]
    pub quant: Option<PathBuf>,
    /// The blob to write.
    #[arg(long, value_name = "X.slm")]
    pub out: PathBuf,
    /// Also write the figures as JSON here.
    #[arg(long, value_name = "FILE")]
    pub json: Option<PathBuf>,
}

/// Runs `semloc convert`.
pub fn run(args: &ConvertArgs) -> Result<()> {
    let quant = args.quant.clone().unwrap_or_else(|| QuantParams::default_path(&args.onnx));
    let converted = convert_files(&args.onnx, &quant)?;
    let blob = converted.encode()?;
    blob.save(&args.out)?;
    let s = ModelSummary::of(&blob.model()?);
    println!("{} + {} -> {}", args.onnx.display(), quant.display(), args.out.display());
    print_summary(&s);
    if let Some(path) = &args.json {
        std::fs::write(path, serde_json::to_string_pretty(&s)?)
            .map_err(|e| anyhow::anyhow!("{}: cannot write: {e}", path.display()))?;
    }
    Ok(())
}

/// Prints a model's figures (also used by `semloc segment`).
pub fn print_summary(s: &ModelSummary) {
    let kinds: Vec<String> = s.ops_by_kind.iter().map(|(k, n)| format!("{k} {n}")).collect();
    println!(
        "input {}x{}, output {} classes x {}x{}",
        s.input_hw.0, s.input_hw.1, s.output_chw.0, s.output_chw.1, s.output_chw.2
    );
    println!("tensors {}, ops {} ({})", s.tensors, s.ops, kinds.join(", "));
    println!("MACs {:.3} G/frame", s.macs as f64 * 1e-9);
    println!(
        "weights {} bytes int8, constant data {} bytes, blob {} bytes",
        s.weight_bytes, s.data_bytes, s.blob_bytes
    );
    println!(
        "activation arena peak {} bytes ({:.2} MiB)",
        s.arena_bytes,
        s.arena_bytes as f64 / 1048576.0
    );
    println!("CRC-32 {:#010x}", s.crc32);
}
