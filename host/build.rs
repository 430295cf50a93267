//! Records the git commit the binary is built from (`SEMLOC_GIT_HASH`, with `-dirty` when
//! tracked files differ from it; `unknown` outside a git checkout, e.g. from a package) for
//! the provenance block of `summary.json`.

use std::process::Command;

fn git(args: &[&str]) -> Option<String> {
    let out = Command::new("git").args(args).output().ok()?;
    out.status.success().then(|| String::from_utf8_lossy(&out.stdout).trim().to_string())
}

fn main() {
    let hash = git(&["rev-parse", "--short=12", "HEAD"]).filter(|h| !h.is_empty());
    let value = match hash {
        Some(h) => {
            let dirty = git(&["status", "--porcelain", "--untracked-files=no"])
                .is_some_and(|s| !s.is_empty());
            if dirty {
                format!("{h}-dirty")
            } else {
                h
            }
        }
        None => "unknown".to_string(),
    };
    println!("cargo:rustc-env=SEMLOC_GIT_HASH={value}");
    // Re-run when HEAD moves or the index changes (a commit, a checkout, `git add`).
    let mut watched = false;
    for rel in ["HEAD", "index"] {
        if let Some(p) = git(&["rev-parse", "--git-path", rel]) {
            let p = std::path::Path::new(&p);
            if p.exists() {
                println!("cargo:rerun-if-changed={}", p.display());
                watched = true;
            }
        }
    }
    if let Some(r) = git(&["symbolic-ref", "-q", "HEAD"]) {
        if let Some(p) = git(&["rev-parse", "--git-path", &r]) {
            if std::path::Path::new(&p).exists() {
                println!("cargo:rerun-if-changed={p}");
            }
        }
    }
    if !watched {
        println!("cargo:rerun-if-changed=build.rs");
    }
}
