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
    // Re-run when HEAD moves (a commit, a checkout: HEAD, the branch's ref, packed-refs) or
    // the code built into this crate changes (the `-dirty` flag: this package, core, the
    // workspace manifest and lock file). Not on `.git/index`: `git status` above rewrites it
    // when it refreshes stat data (right after a clone it always does), so watching it re-ran
    // this script, and rebuilt this crate and all that depends on it, in the build after.
    let mut watched = Vec::new();
    let head_ref = git(&["symbolic-ref", "-q", "HEAD"]);
    for rel in ["HEAD", "packed-refs"].into_iter().map(String::from).chain(head_ref) {
        if let Some(p) = git(&["rev-parse", "--git-path", &rel]) {
            if std::path::Path::new(&p).exists() {
                watched.push(p);
            }
        }
    }
    if watched.is_empty() {
        println!("cargo:rerun-if-changed=build.rs");
    } else {
        for p in watched.iter().map(String::as_str).chain(["src", "build.rs", "Cargo.toml"]) {
            println!("cargo:rerun-if-changed={p}");
        }
        for p in ["../core/src", "../core/Cargo.toml", "../Cargo.toml", "../Cargo.lock"] {
            if std::path::Path::new(p).exists() {
                println!("cargo:rerun-if-changed={p}");
            }
        }
    }
}
