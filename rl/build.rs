//! Records which source the program is built from, for the run directories' `builds.csv`
//! (`rl::app::build_info`): `MEBEN_COMMIT` is the git commit of the checkout, with
//! `+modified` when the program's sources (the five crates, `Cargo.toml`, `Cargo.lock`)
//! differ from it (`+unknown-status` when `git status` fails), or `unknown` outside a git
//! checkout or without git.
//!
//! The script reruns when the commit can have changed (git's `HEAD`, the current branch's
//! ref, `packed-refs`) or a source of the program did; only paths that exist are watched,
//! since cargo reruns a script on every build while a watched path is missing.

use std::path::{Path, PathBuf};
use std::process::Command;

/// The program's sources, relative to the workspace root (`git status` and the watch list).
const SOURCES: [&str; 7] = ["tensor", "nn", "models", "envs", "rl", "Cargo.toml", "Cargo.lock"];

fn git(root: &Path, args: &[&str]) -> Option<String> {
    let out = Command::new("git").arg("-C").arg(root).args(args).output().ok()?;
    out.status.success().then(|| String::from_utf8_lossy(&out.stdout).trim().to_string())
}

fn main() {
    let manifest = PathBuf::from(std::env::var("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR"));
    let root = manifest.parent().expect("rl sits in the workspace root").to_path_buf();
    let mut watched: Vec<PathBuf> = SOURCES.iter().map(|s| root.join(s)).collect();
    let commit = match git(&root, &["rev-parse", "HEAD"]) {
        Some(sha) if !sha.is_empty() => {
            let mut refs = vec!["HEAD".to_string(), "packed-refs".to_string()];
            refs.extend(git(&root, &["symbolic-ref", "-q", "HEAD"]));
            for r in refs {
                if let Some(p) = git(&root, &["rev-parse", "--git-path", &r]) {
                    watched.push(root.join(p));
                }
            }
            let mut status = vec!["status", "--porcelain", "--untracked-files=no", "--"];
            status.extend(SOURCES);
            match git(&root, &status) {
                Some(s) if s.is_empty() => sha,
                Some(_) => format!("{sha}+modified"),
                None => format!("{sha}+unknown-status"),
            }
        }
        _ => "unknown".to_string(),
    };
    for p in watched.iter().filter(|p| p.exists()) {
        println!("cargo:rerun-if-changed={}", p.display());
    }
    println!("cargo:rustc-env=MEBEN_COMMIT={commit}");
}
