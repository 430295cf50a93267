//! Decodes the embedded sequence (`data/manifest.txt`, `data/{left,right}_NN.png`) into raw
//! luma files in `OUT_DIR` and writes `embedded_data.rs` (see `src/embedded.rs`), and gives
//! the bare-metal binaries their linker scripts.

use core::fmt::Write as _;
use std::path::{Path, PathBuf};

fn main() {
    let dir = PathBuf::from(std::env::var("CARGO_MANIFEST_DIR").expect("CARGO_MANIFEST_DIR"));
    let out = PathBuf::from(std::env::var("OUT_DIR").expect("OUT_DIR"));
    embed(&dir.join("data"), &out);
    link_scripts(&dir);
}

/// Per-binary linker scripts, only for the bare-metal targets each binary is meant for (the
/// binaries are stubs elsewhere).
fn link_scripts(dir: &Path) {
    let target = std::env::var("TARGET").unwrap_or_default();
    for script in ["qemu_virt.ld", "thumbv7em.ld"] {
        println!("cargo:rerun-if-changed={}", dir.join(script).display());
    }
    if target == "aarch64-unknown-none" {
        let ld = dir.join("qemu_virt.ld");
        println!("cargo:rustc-link-arg-bin=qemu_aarch64=-T{}", ld.display());
    } else if target.starts_with("thumbv7em-") && target.contains("-none-") {
        let ld = dir.join("thumbv7em.ld");
        println!("cargo:rustc-link-arg-bin=thumbv7em_size=-T{}", ld.display());
    }
}

fn fail(msg: String) -> ! {
    panic!("firmware-sim build script: {msg}")
}

fn embed(data: &Path, out: &Path) {
    let manifest = data.join("manifest.txt");
    println!("cargo:rerun-if-changed={}", manifest.display());
    let text = match std::fs::read_to_string(&manifest) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            // Only while bootstrapping data/ with examples/make_frames.rs (which needs this
            // crate to build): no frames, and the tests say so.
            println!("cargo:warning=no {}: embedding no frames", manifest.display());
            String::from(
                "source none\nwidth 640\nheight 192\ncrop_x 0\ncrop_y 0\nfx_px 1\nfy_px 1\n\
                 cx_px 0\ncy_px 0\nbaseline_m 1\n",
            )
        }
        Err(e) => fail(format!("{}: {e}", manifest.display())),
    };
    let mut kv = std::collections::BTreeMap::new();
    let mut frames: Vec<(f64, Vec<f64>)> = Vec::new();
    let mut source = String::new();
    for line in text.lines().map(str::trim).filter(|l| !l.is_empty() && !l.starts_with('#')) {
        let (key, rest) = line.split_once(' ').unwrap_or((line, ""));
        match key {
            "source" => source = rest.trim().to_string(),
            "frame" => {
                let nums: Vec<f64> = rest
                    .split_whitespace()
                    .map(|t| t.parse().unwrap_or_else(|e| fail(format!("`{line}`: {e}"))))
                    .collect();
                if nums.len() != 14 || nums[0] as usize != frames.len() {
                    fail(format!("`{line}`: want `frame INDEX TIME_S R00 .. T2` in order"));
                }
                frames.push((nums[1], nums[2..].to_vec()));
            }
            _ => {
                let v: f64 = rest.trim().parse().unwrap_or_else(|e| fail(format!("`{line}`: {e}")));
                kv.insert(key.to_string(), v);
            }
        }
    }
    let get = |k: &str| -> f64 {
        *kv.get(k).unwrap_or_else(|| fail(format!("{}: no `{k}`", manifest.display())))
    };
    let (w, h) = (get("width") as usize, get("height") as usize);
    let mut rs = String::new();
    let _ = writeln!(rs, "/// Image width (px).\npub const WIDTH: usize = {w};");
    let _ = writeln!(rs, "/// Image height (px).\npub const HEIGHT: usize = {h};");
    let _ = writeln!(
        rs,
        "/// Where the crop sits in the source frame (px): left column, top row.\n\
         pub const CROP_ORIGIN: (usize, usize) = ({}, {});",
        get("crop_x") as usize,
        get("crop_y") as usize
    );
    let _ =
        writeln!(rs, "/// How the source sequence was made.\npub const SOURCE: &str = {source:?};");
    let _ = writeln!(
        rs,
        "/// The crop's rectified stereo camera.\npub const CAMERA: StereoCamera = StereoCamera \
         {{ fx_px: {:?}, fy_px: {:?}, cx_px: {:?}, cy_px: {:?}, baseline_m: {:?} }};",
        get("fx_px"),
        get("fy_px"),
        get("cx_px"),
        get("cy_px"),
        get("baseline_m")
    );
    let _ = writeln!(
        rs,
        "/// The frames, in order.\npub const FRAMES: [EmbeddedFrame; {}] = [",
        frames.len()
    );
    for (i, (t, pose)) in frames.iter().enumerate() {
        let mut paths = Vec::new();
        for side in ["left", "right"] {
            let png = data.join(format!("{side}_{i:02}.png"));
            println!("cargo:rerun-if-changed={}", png.display());
            let luma = decode_grey_png(&png, w, h)
                .unwrap_or_else(|e| fail(format!("{}: {e}", png.display())));
            let raw = out.join(format!("{side}_{i:02}.luma"));
            std::fs::write(&raw, &luma).unwrap_or_else(|e| fail(format!("{}: {e}", raw.display())));
            paths.push(raw);
        }
        let pose: Vec<String> = pose.iter().map(|x| format!("{x:?}")).collect();
        let _ = writeln!(
            rs,
            "    EmbeddedFrame {{ left: include_bytes!({:?}), right: include_bytes!({:?}), \
             timestamp_s: {t:?}, gt_pose: [{}] }},",
            paths[0].display().to_string(),
            paths[1].display().to_string(),
            pose.join(", ")
        );
    }
    rs.push_str("];\n");
    // The int8 segmentation network for 192x640 inputs (the crop's size: letterbox factor 1),
    // read in place from `.rodata`; the core parser wants it 4-byte aligned.
    let model = data.join("../../models/artefacts/fastscnn_r2_192x640.slm");
    println!("cargo:rerun-if-changed={}", model.display());
    if !model.exists() {
        fail(format!("{}: missing", model.display()));
    }
    let _ = writeln!(
        rs,
        "/// File name of the embedded network.\npub const MODEL_NAME: &str = \"fastscnn_r2_192x640.slm\";\n\
         static MODEL_ALIGNED: &Aligned<[u8]> = &Aligned(*include_bytes!({:?}));",
        model.display().to_string()
    );
    let path = out.join("embedded_data.rs");
    std::fs::write(&path, rs).unwrap_or_else(|e| fail(format!("{}: {e}", path.display())));
}

/// Decodes an 8-bit grey PNG of `w`×`h` pixels (what `examples/make_frames.rs` writes) to its
/// row-major bytes. The `png` crate alone: `image` as a build dependency was built in full by
/// every `cargo clippy` and bare-metal build (it and its colour-management crates, ~70 s).
fn decode_grey_png(path: &Path, w: usize, h: usize) -> Result<Vec<u8>, String> {
    let file = std::fs::File::open(path).map_err(|e| e.to_string())?;
    let mut dec = png::Decoder::new(std::io::BufReader::new(file));
    dec.set_transformations(png::Transformations::IDENTITY);
    let mut reader = dec.read_info().map_err(|e| e.to_string())?;
    let (cw, cd) = reader.output_color_type();
    if (cw, cd) != (png::ColorType::Grayscale, png::BitDepth::Eight) {
        return Err(format!("{cw:?} {cd:?}, want 8-bit grey"));
    }
    let info = reader.info();
    if (info.width as usize, info.height as usize) != (w, h) {
        return Err(format!("{}x{}, manifest says {w}x{h}", info.width, info.height));
    }
    let mut buf = vec![0u8; reader.output_buffer_size().ok_or("image too large")?];
    let frame = reader.next_frame(&mut buf).map_err(|e| e.to_string())?;
    buf.truncate(frame.buffer_size());
    if buf.len() != w * h {
        return Err(format!("{} bytes decoded, want {}", buf.len(), w * h));
    }
    Ok(buf)
}
