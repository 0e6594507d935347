//! The process's own memory limits (issue 77 item 10), which can be far below what the
//! machine has free: its resource limits (`ulimit -v`: `RLIMIT_AS`; `ulimit -d`:
//! `RLIMIT_DATA`; read from `/proc/self/limits`, less what the process already uses of them:
//! `VmSize` and `VmData` of `/proc/self/status`) and its control group's (cgroup v2:
//! `memory.max` minus `memory.current`; cgroup v1: `memory.limit_in_bytes` minus
//! `memory.usage_in_bytes`; of the group `/proc/self/cgroup` names and each of its
//! ancestors, since a parent's limit binds too). [`crate::memory::machine_memory`] takes the
//! smallest of these and the machine's. Each parser takes the file's text, so it is tested
//! on text.

use std::path::{Path, PathBuf};

/// Values at or above this (2^60 bytes) mean "no limit" (cgroup v1 writes
/// 9223372036854771712 for none).
const UNLIMITED: u128 = 1 << 60;

/// One limit of the process: bytes it may still allocate, and where that comes from.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ProcessLimit {
    /// Bytes left under the limit.
    pub bytes: u128,
    /// What the limit is, for messages (`RLIMIT_AS (ulimit -v) minus VmSize`,
    /// `memory.max minus memory.current of /sys/fs/cgroup/x`).
    pub source: String,
}

/// The soft limit of the resource `name` (`Max address space`, `Max data size`) in the text
/// of `/proc/self/limits`, in bytes; `None` when unlimited or absent.
pub fn parse_rlimit(text: &str, name: &str) -> Option<u128> {
    let line = text.lines().find(|l| l.starts_with(name))?;
    let soft = line[name.len()..].split_whitespace().next()?;
    soft.parse::<u128>().ok().filter(|&b| b < UNLIMITED)
}

/// The field `name` (`VmSize`, `VmData`) of the text of `/proc/self/status`, in bytes.
pub fn parse_status_kb(text: &str, name: &str) -> Option<u128> {
    let line = text.lines().find(|l| l.split(':').next() == Some(name))?;
    let kb: u128 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

/// The control group paths of the text of `/proc/self/cgroup`: the cgroup v2 path (the
/// `0::<path>` line) and the cgroup v1 path of the `memory` controller.
pub fn parse_cgroup_paths(text: &str) -> (Option<String>, Option<String>) {
    let (mut v2, mut v1) = (None, None);
    for line in text.lines() {
        let mut parts = line.splitn(3, ':');
        let (Some(id), Some(controllers), Some(path)) = (parts.next(), parts.next(), parts.next()) else { continue };
        if id == "0" && controllers.is_empty() {
            v2 = Some(path.to_string());
        } else if controllers.split(',').any(|c| c == "memory") {
            v1 = Some(path.to_string());
        }
    }
    (v2, v1)
}

/// A cgroup memory file's value (`memory.max`, `memory.limit_in_bytes`, ...): `None` for
/// `max`, a value meaning no limit, or text that is not a number.
pub fn parse_cgroup_value(text: &str) -> Option<u128> {
    text.trim().parse::<u128>().ok().filter(|&b| b < UNLIMITED)
}

/// The limit of `limit` less `used` (saturating), described as `what`.
fn left(limit: Option<u128>, used: Option<u128>, source: String) -> Option<ProcessLimit> {
    limit.map(|l| ProcessLimit { bytes: l.saturating_sub(used.unwrap_or(0)), source })
}

/// The resource limits of the process (module docs), from `/proc/self`.
fn rlimits() -> Vec<ProcessLimit> {
    let Ok(limits) = std::fs::read_to_string("/proc/self/limits") else { return Vec::new() };
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    let each = [
        ("Max address space", "VmSize", "the address-space limit RLIMIT_AS (ulimit -v) less VmSize"),
        ("Max data size", "VmData", "the data-segment limit RLIMIT_DATA (ulimit -d) less VmData"),
    ];
    each.iter()
        .filter_map(|(name, used, what)| {
            left(parse_rlimit(&limits, name), parse_status_kb(&status, used), format!("{what} of /proc/self"))
        })
        .collect()
}

/// The directories of the group `path` under the hierarchy mounted at `root`, the group's
/// own first, then each ancestor up to `root` itself (only those that exist: in a container
/// the group's own directory is often the mount's root).
fn group_dirs(root: &Path, path: &str) -> Vec<PathBuf> {
    let mut dirs = Vec::new();
    let mut p = Some(Path::new(path.trim_start_matches('/')));
    while let Some(rel) = p {
        let dir = root.join(rel);
        if dir.is_dir() && !dirs.contains(&dir) {
            dirs.push(dir);
        }
        p = rel.parent();
    }
    dirs
}

/// The control group limits of the process (module docs).
fn cgroup_limits() -> Vec<ProcessLimit> {
    let Ok(text) = std::fs::read_to_string("/proc/self/cgroup") else { return Vec::new() };
    let read = |p: PathBuf| std::fs::read_to_string(p).ok().and_then(|t| parse_cgroup_value(&t));
    let (v2, v1) = parse_cgroup_paths(&text);
    let mut out = Vec::new();
    let mut add = |root: &Path, path: &str, max: &str, current: &str| {
        for dir in group_dirs(root, path) {
            let what = format!("{max} minus {current} of {}", dir.display());
            out.extend(left(read(dir.join(max)), read(dir.join(current)), what));
        }
    };
    if let Some(p) = v2 {
        add(Path::new("/sys/fs/cgroup"), &p, "memory.max", "memory.current");
        add(Path::new("/sys/fs/cgroup/unified"), &p, "memory.max", "memory.current");
    }
    if let Some(p) = v1 {
        add(Path::new("/sys/fs/cgroup/memory"), &p, "memory.limit_in_bytes", "memory.usage_in_bytes");
    }
    out
}

/// Every memory limit of this process (module docs); empty where there is none or the OS
/// does not say.
pub fn process_limits() -> Vec<ProcessLimit> {
    let mut all = rlimits();
    all.extend(cgroup_limits());
    all
}

#[cfg(test)]
mod tests {
    use super::*;

    const LIMITS: &str = "Limit                     Soft Limit           Hard Limit           Units     \n\
        Max cpu time              unlimited            unlimited            seconds   \n\
        Max data size             unlimited            unlimited            bytes     \n\
        Max stack size            8388608              unlimited            bytes     \n\
        Max address space         4294967296           unlimited            bytes     \n";

    #[test]
    fn rlimits_give_the_soft_limit_and_unlimited_is_none() {
        assert_eq!(parse_rlimit(LIMITS, "Max address space"), Some(4_294_967_296));
        assert_eq!(parse_rlimit(LIMITS, "Max data size"), None);
        assert_eq!(parse_rlimit(LIMITS, "Max resident set"), None);
        assert_eq!(parse_rlimit("", "Max address space"), None);
        let status = "Name:\tmeben\nVmPeak:\t  200 kB\nVmSize:\t  100 kB\nVmData:\t   40 kB\n";
        assert_eq!(parse_status_kb(status, "VmSize"), Some(102_400));
        assert_eq!(parse_status_kb(status, "VmData"), Some(40_960));
        assert_eq!(parse_status_kb(status, "VmRSS"), None);
        let l = left(Some(1000), Some(300), "x".into()).unwrap();
        assert_eq!(l.bytes, 700);
        assert_eq!(left(Some(100), Some(300), "x".into()).unwrap().bytes, 0);
        assert_eq!(left(None, Some(1), "x".into()), None);
    }

    #[test]
    fn cgroup_files_give_paths_and_limits() {
        let v1 = "9:name=systemd:/\n5:devices:/\n4:cpu,memory:/process_api/0d55\n1:cpu:/\n0::/\n";
        assert_eq!(parse_cgroup_paths(v1), (Some("/".into()), Some("/process_api/0d55".into())));
        assert_eq!(
            parse_cgroup_paths("0::/user.slice/session-1.scope\n"),
            (Some("/user.slice/session-1.scope".into()), None)
        );
        assert_eq!(parse_cgroup_paths("garbage"), (None, None));
        assert_eq!(parse_cgroup_value("max\n"), None);
        assert_eq!(parse_cgroup_value("2147483648\n"), Some(2_147_483_648));
        assert_eq!(parse_cgroup_value("9223372036854771712\n"), None);
        assert_eq!(parse_cgroup_value(""), None);
        // A group's own directory and its ancestors, those that exist.
        let root = std::env::temp_dir().join(format!("meben-cgroup-{}", std::process::id()));
        std::fs::create_dir_all(root.join("a/b")).unwrap();
        assert_eq!(group_dirs(&root, "/a/b/c"), [root.join("a/b"), root.join("a"), root.clone()]);
        assert_eq!(group_dirs(&root, "/"), std::slice::from_ref(&root));
        std::fs::remove_dir_all(&root).unwrap();
    }
}
