//! docs/outputs.md stays honest: a short synthetic run's `frames.csv` columns, the keys of its
//! `summary.json` and `eval.json` (top level and nested blocks) and its plot files are each
//! named in their section of the page, and the page's tables list no column or key that the
//! files do not have.

use std::collections::BTreeSet;
use std::path::Path;

use semloc::dataset::Sequence;
use semloc::run::{frames_csv_header, RunConfig, Semantics};
use semloc::synth::{generate, Dynamics, SynthConfig};

fn doc() -> String {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/outputs.md");
    std::fs::read_to_string(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

/// The text of the section whose heading line contains `heading`, up to the next heading of
/// the same or a higher level.
fn section<'a>(doc: &'a str, heading: &str) -> &'a str {
    let start = doc
        .lines()
        .scan(0usize, |pos, l| {
            let at = *pos;
            *pos += l.len() + 1;
            Some((at, l))
        })
        .find(|(_, l)| l.starts_with('#') && l.contains(heading))
        .unwrap_or_else(|| panic!("docs/outputs.md has no section {heading:?}"));
    let level = start.1.chars().take_while(|&c| c == '#').count();
    let body = &doc[start.0 + start.1.len()..];
    let end = body
        .lines()
        .scan(0usize, |pos, l| {
            let at = *pos;
            *pos += l.len() + 1;
            Some((at, l))
        })
        .find(|(_, l)| {
            let n = l.chars().take_while(|&c| c == '#').count();
            n > 0 && n <= level
        })
        .map_or(body.len(), |(at, _)| at);
    &body[..end]
}

/// The first cells of a section's table rows that name a field (`` | `name` | ... ``).
fn table_names(section: &str) -> BTreeSet<String> {
    section
        .lines()
        .filter_map(|l| l.strip_prefix("| `"))
        .filter_map(|l| l.split('`').next())
        .map(str::to_owned)
        .collect()
}

fn mentions(section: &str, key: &str) -> bool {
    section.contains(&format!("`{key}`")) || section.contains(&format!("\"{key}\""))
}

/// Every key of `v` and of the objects nested in it (through lists too), except below the
/// keys in `opaque` (blocks documented elsewhere, e.g. the tracker settings).
fn keys(v: &serde_json::Value, opaque: &[&str], out: &mut BTreeSet<String>) {
    match v {
        serde_json::Value::Object(m) => {
            for (k, child) in m {
                out.insert(k.clone());
                if !opaque.contains(&k.as_str()) {
                    keys(child, opaque, out);
                }
            }
        }
        serde_json::Value::Array(a) => a.iter().for_each(|c| keys(c, opaque, out)),
        _ => {}
    }
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

#[test]
fn every_output_field_is_documented() {
    let doc = doc();
    let dir = tempfile::tempdir().unwrap();
    let cfg =
        SynthConfig { frames: 40, dynamics: Dynamics::High, seed: 5, ..SynthConfig::default() };
    generate(&dir.path().join("seq"), &cfg).unwrap();
    let seq = Sequence::open_odometry(&dir.path().join("seq"), &cfg.seq, None).unwrap();
    let out = dir.path().join("out");
    // Motion-aware semantics on a sequence with a moving-object mask: `motion` and its
    // `moving_check` are filled in, not null.
    let r =
        semloc::run::run(RunConfig { semantics: Semantics::Motion, ..RunConfig::new(&seq, &out) })
            .unwrap();
    assert!(r.failure.is_none() && r.eval_error.is_none(), "{:?}", r.failure);

    // frames.csv: the file's header is the serde struct's, and the doc's table is exactly it.
    let text = std::fs::read_to_string(out.join("frames.csv")).unwrap();
    assert_eq!(text.lines().next(), Some(frames_csv_header()));
    let frames = section(&doc, "### frames.csv");
    let columns: BTreeSet<String> = frames_csv_header().split(',').map(str::to_owned).collect();
    assert_eq!(table_names(frames), columns, "docs/outputs.md frames.csv table vs the columns");

    // summary.json and eval.json: every key named; every documented top-level key real.
    for (name, opaque) in
        [("summary.json", &["orb", "stereo", "tracker"][..]), ("eval.json", &[][..])]
    {
        let v = json(&out.join(name));
        let sec = section(&doc, &format!("### {name}"));
        let mut all = BTreeSet::new();
        keys(&v, opaque, &mut all);
        let missing: Vec<_> = all.iter().filter(|k| !mentions(sec, k)).collect();
        assert!(missing.is_empty(), "{name} keys not in docs/outputs.md: {missing:?}");
        let top: BTreeSet<String> = v.as_object().unwrap().keys().cloned().collect();
        assert_eq!(table_names(sec), top, "docs/outputs.md {name} table vs the file's keys");
    }
    assert!(json(&out.join("summary.json"))["motion"]["moving_check"].is_object());

    // plots: every file is documented as NAME.svg / NAME.png.
    let plots = section(&doc, "### plots/");
    let mut stems = BTreeSet::new();
    for e in std::fs::read_dir(out.join("plots")).unwrap() {
        let p = e.unwrap().path();
        let ext = p.extension().unwrap().to_string_lossy().into_owned();
        assert!(ext == "svg" || ext == "png", "unexpected plot file {}", p.display());
        stems.insert(p.file_stem().unwrap().to_string_lossy().into_owned());
    }
    assert_eq!(table_names(plots), stems, "docs/outputs.md plots table vs plots/");

    // The run's folder: every entry it wrote is documented in the run section.
    let run = section(&doc, "## `semloc run");
    for e in std::fs::read_dir(&out).unwrap() {
        let name = e.unwrap().file_name().to_string_lossy().into_owned();
        let shown = if name == "plots" { "plots/".to_owned() } else { name.clone() };
        assert!(mentions(run, &shown), "{name} not in the run section of docs/outputs.md");
    }
}

/// The files `semloc gt` writes are the ones the page lists.
#[test]
fn gt_files_are_documented() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = SynthConfig { frames: 4, dynamics: Dynamics::Static, ..SynthConfig::default() };
    generate(&dir.path().join("seq"), &cfg).unwrap();
    let out = dir.path().join("gt");
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_semloc"))
        .args(["gt", dir.path().join("seq").to_str().unwrap(), "--seq", &cfg.seq, "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let written: BTreeSet<String> = std::fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(table_names(section(&doc(), "## `semloc gt")), written);
}

/// The README links the page.
#[test]
fn readme_links_the_page() {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../README.md");
    let readme = std::fs::read_to_string(p).unwrap();
    assert!(readme.contains("(docs/outputs.md)"), "README.md does not link docs/outputs.md");
}
