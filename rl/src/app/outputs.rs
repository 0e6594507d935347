//! Where a command may write: every command that writes a file a person names (`meben eval
//! --out`, `render --out`, `export-policy --out`, `sim --out`) checks it with
//! [`check_output`] before it reads or computes anything, so that it never replaces a run
//! directory's own files ([`crate::app::run_dir::check_not_a_run_file`]) nor one of its
//! own inputs (`meben eval --policy F --out F`). Paths are compared as they lead on disk
//! ([`resolved`]: through `..`, `.` and symbolic links, also for a file not yet written).

use std::path::{Component, Path, PathBuf};

use crate::error::{Result, RlError};

/// Refuses `out` as the output of the command-line option `option` when it is one of a run
/// directory's own files, or the same file as one of `inputs` (`(option, path)` pairs, e.g.
/// `("--policy", path)`). The error names `option`, the path and what it would overwrite.
pub fn check_output(option: &str, out: &Path, inputs: &[(&str, &Path)]) -> Result<()> {
    crate::app::run_dir::check_not_a_run_file(option, out)?;
    let target = resolved(out);
    for (input_option, input) in inputs {
        if resolved(input) == target {
            return Err(RlError::file(
                out,
                format!("{option} would overwrite the {input_option} input {}; write to another file", input.display()),
            ));
        }
    }
    Ok(())
}

/// `path` as it leads on disk: its longest existing ancestor canonicalised (symbolic links
/// and `..` resolved), the rest appended with `.` dropped and `..` taking off the last
/// component. Relative paths are taken from the current directory. Two paths to one file,
/// existing or not yet, resolve to the same value.
pub fn resolved(path: &Path) -> PathBuf {
    let absolute = if path.is_absolute() {
        path.to_path_buf()
    } else {
        std::env::current_dir().map(|d| d.join(path)).unwrap_or_else(|_| path.to_path_buf())
    };
    // The longest prefix that exists, canonicalised, and the components after it.
    let mut base = absolute.as_path();
    let mut rest: Vec<Component> = Vec::new();
    let canonical = loop {
        if let Ok(c) = base.canonicalize() {
            break c;
        }
        match (base.parent(), base.components().next_back()) {
            (Some(parent), Some(last)) => {
                rest.push(last);
                base = parent;
            }
            _ => break base.to_path_buf(),
        }
    };
    let mut out = canonical;
    for c in rest.into_iter().rev() {
        match c {
            Component::CurDir => {}
            Component::ParentDir => {
                out.pop();
            }
            c => out.push(c),
        }
    }
    out
}

/// Whether `inner` lies inside `outer` or is it, both [`resolved`].
pub fn is_within(inner: &Path, outer: &Path) -> bool {
    resolved(inner).starts_with(resolved(outer))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::app::test_util::TempDir;

    #[test]
    fn paths_to_one_file_resolve_alike_written_or_not() {
        let dir = TempDir::new("outputs-resolved");
        std::fs::create_dir_all(dir.0.join("a/b")).unwrap();
        std::fs::write(dir.0.join("a/f"), "x").unwrap();
        assert_eq!(resolved(&dir.0.join("a/b/../f")), resolved(&dir.0.join("a/f")));
        assert_eq!(resolved(&dir.0.join("a/new/./../g")), resolved(&dir.0.join("a/g")));
        assert!(is_within(&dir.0.join("a/new/deeper"), &dir.0.join("a")));
        assert!(is_within(&dir.0.join("a"), &dir.0.join("a/b/..")));
        assert!(!is_within(&dir.0.join("ab"), &dir.0.join("a")));
        #[cfg(unix)]
        {
            std::os::unix::fs::symlink(dir.0.join("a"), dir.0.join("link")).unwrap();
            assert!(is_within(&dir.0.join("link/x/y"), &dir.0.join("a")));
        }
    }

    /// Issue 77 item 1: `meben eval --policy F --out F` replaced the policy with the
    /// evaluation's summary. An output that is one of the command's inputs is refused, by
    /// any path that leads to it; a run directory's own files still are.
    #[test]
    fn an_input_and_a_run_file_are_refused_as_outputs() {
        let dir = TempDir::new("outputs-inputs");
        let policy = dir.0.join("p.safetensors");
        std::fs::write(&policy, "policy").unwrap();
        let inputs = [("--policy", policy.as_path())];
        let e = check_output("--out", &dir.0.join("./p.safetensors"), &inputs).unwrap_err().to_string();
        assert!(e.contains("--out") && e.contains("--policy") && e.contains("p.safetensors"), "{e}");
        check_output("--out", &dir.0.join("summary.json"), &inputs).unwrap();
        let run = dir.0.join("run");
        std::fs::create_dir_all(&run).unwrap();
        std::fs::write(run.join("config.toml"), "").unwrap();
        let e = check_output("--out", &run.join("checkpoint.json"), &inputs).unwrap_err().to_string();
        assert!(e.contains("checkpoint.json") && e.contains("own"), "{e}");
    }
}
