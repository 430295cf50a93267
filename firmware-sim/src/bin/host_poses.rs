//! Runs the embedded frames through [`Localiser`] on the host (std) and prints the same report
//! as the bare-metal image (`semloc_firmware_sim::report`): first the geometric pipeline, then
//! the semantic one (int8 network, semantic ORB, EM association). Exits 0 when the tracker
//! tracked in both runs, 2 when it did not, 1 on an error.
//!
//! ```text
//! cargo run --release -p semloc-firmware-sim --bin host_poses
//! ```
#![forbid(unsafe_code)]

use std::io::Write as _;
use std::process::ExitCode;

use semloc_firmware_sim::embedded::{HEIGHT, MODEL_BLOB, WIDTH};
use semloc_firmware_sim::report::{self, RunError};
use semloc_firmware_sim::{
    embedded_localiser, geometric_params, semantic_params, Network, SegStorage, SEMANTIC_SCHEME,
};

/// Stack for the thread that builds the ≈ 41 MiB localiser (a by-value return may sit on it).
const BIG_STACK_BYTES: usize = 1 << 30;

/// Both runs; the text so far even on failure, and whether both tracked.
fn run(text: &mut String) -> Result<bool, String> {
    let err = |e: RunError| e.to_string();
    let mut loc =
        Box::new(embedded_localiser(geometric_params(), None).map_err(|e| e.to_string())?);
    let geometric = report::run_embedded(&mut loc, None, text, |_, _| Ok(())).map_err(err)?;
    *loc =
        embedded_localiser(semantic_params(), Some(SEMANTIC_SCHEME)).map_err(|e| e.to_string())?;
    let mut storage = Box::new(SegStorage::new());
    let mut sem =
        Network::new(MODEL_BLOB, WIDTH, HEIGHT, storage.memory()).map_err(|e| e.to_string())?;
    let semantic =
        report::run_embedded(&mut loc, Some(&mut sem), text, |_, _| Ok(())).map_err(err)?;
    Ok(geometric.tracked() && semantic.tracked())
}

fn main() -> ExitCode {
    let worker = std::thread::Builder::new().stack_size(BIG_STACK_BYTES).spawn(|| {
        let mut text = String::new();
        let r = run(&mut text);
        (text, r)
    });
    let (text, result) = match worker.map(|h| h.join()) {
        Ok(Ok(out)) => out,
        _ => {
            eprintln!("host_poses: worker thread failed");
            return ExitCode::from(1);
        }
    };
    let mut out = std::io::stdout().lock();
    if out.write_all(text.as_bytes()).and_then(|()| out.flush()).is_err() {
        return ExitCode::from(1);
    }
    match result {
        Ok(true) => ExitCode::SUCCESS,
        Ok(false) => ExitCode::from(2),
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::from(1)
        }
    }
}
