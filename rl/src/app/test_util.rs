//! Helpers of the unit tests.

use std::path::{Path, PathBuf};

/// A fresh directory under the system's temporary directory, removed when dropped.
pub(crate) struct TempDir(pub(crate) PathBuf);

impl TempDir {
    /// `<tmp>/rl-<name>-<pid>`, emptied first.
    pub(crate) fn new(name: &str) -> TempDir {
        let p = std::env::temp_dir().join(format!("rl-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&p);
        std::fs::create_dir_all(&p).unwrap();
        TempDir(p)
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// The simulator's test ant (an MJCF file).
pub(crate) const ANT_XML: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../envs/tests/data/ant.xml");

/// A morphology file `dir/body.xml` (a copy of the simulator's test ant), for runs on a
/// user's file.
pub(crate) fn ant_body(dir: &Path) -> PathBuf {
    let body = dir.join("body.xml");
    std::fs::copy(ANT_XML, &body).unwrap();
    body
}
