//! Atomic file writes: the bytes go to a temporary sibling file, are synced, and the file is
//! renamed over the target, so a crash leaves the old or the new version, never half of one.
//!
//! The temporary name is unique to the process and the call (`.<name>.<pid>.<n>.tmp`), so
//! two processes or threads writing the same file never write through one temporary file; a
//! failed write removes its temporary file (after a full disk it would otherwise hold the
//! space and every later attempt would fail again). Temporary files of a process killed
//! mid-write match [`is_temporary`] and can be removed by whoever owns the directory.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use crate::error::{NnError, Result};

/// Calls of [`write_atomic`] in this process, to make temporary names unique per call.
static WRITES: AtomicU64 = AtomicU64::new(0);

/// The suffix of every temporary file of [`write_atomic`].
const SUFFIX: &str = ".tmp";

/// A temporary sibling of `path` unique to this process and call.
fn temporary_path(path: &Path) -> PathBuf {
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let n = WRITES.fetch_add(1, Ordering::Relaxed);
    path.with_file_name(format!(".{name}.{}.{n}{SUFFIX}", std::process::id()))
}

/// Whether `file_name` is a temporary file of [`write_atomic`] (of any process), or of the
/// versions before per-process names (`<name>.tmp`).
pub fn is_temporary(file_name: &str) -> bool {
    file_name.ends_with(SUFFIX)
}

/// Writes `bytes` to `path` atomically (module docs). On error the temporary file is
/// removed and `path` is unchanged.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let tmp = temporary_path(path);
    let written = (|| {
        let mut f = std::fs::File::create_new(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        drop(f);
        std::fs::rename(&tmp, path)
    })();
    written.map_err(|source| {
        let _ = std::fs::remove_file(&tmp);
        NnError::Io { path: path.into(), source }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn temp_dir(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("nn-atomic-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    fn entries(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> =
            std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
        v.sort();
        v
    }

    #[test]
    fn a_failed_write_leaves_no_temporary_file() {
        let dir = temp_dir("fail");
        // Renaming a file over a directory fails after the temporary file was written.
        let target = dir.join("state.json");
        std::fs::create_dir(&target).unwrap();
        let e = write_atomic(&target, b"payload").unwrap_err();
        assert!(e.to_string().contains("state.json"), "{e}");
        assert_eq!(entries(&dir), ["state.json"]);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn concurrent_writers_of_one_file_do_not_collide() {
        let dir = temp_dir("race");
        let target = dir.join("metrics.csv");
        std::thread::scope(|s| {
            for k in 0..8 {
                let target = &target;
                s.spawn(move || {
                    let text = format!("writer {k}\n").repeat(1000);
                    for _ in 0..50 {
                        write_atomic(target, text.as_bytes()).unwrap();
                    }
                });
            }
        });
        let text = std::fs::read_to_string(&target).unwrap();
        let first = text.lines().next().unwrap().to_string();
        assert!(text.lines().all(|l| l == first) && text.lines().count() == 1000, "a mixed file");
        assert_eq!(entries(&dir), ["metrics.csv"]);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn temporary_names_are_recognised_and_unique() {
        let p = Path::new("/x/checkpoint.json");
        let (a, b) = (temporary_path(p), temporary_path(p));
        assert_ne!(a, b);
        for t in [&a, &b] {
            assert_eq!(t.parent(), p.parent());
            assert!(is_temporary(&t.file_name().unwrap().to_string_lossy()));
        }
        assert!(is_temporary("checkpoint.json.tmp"));
        assert!(!is_temporary("checkpoint.json"));
    }
}
