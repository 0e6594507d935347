//! The machine's memory, so that sizes it cannot hold are refused before they are
//! allocated (an error naming the size, not `memory allocation of N bytes failed` and an
//! aborted process).
//!
//! The bound is `MemAvailable` of `/proc/meminfo`: what the kernel says can be allocated now
//! without swapping (free memory plus caches it can drop). Where that line is missing (Linux
//! before 3.14) `MemTotal` is used, and where there is no `/proc/meminfo` (not Linux) nothing
//! is refused. Every message says which bound it used.

use std::fmt;

/// How much memory the machine offers, and where the figure comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MachineMemory {
    /// Bytes.
    pub bytes: u128,
    /// The `/proc/meminfo` line it was read from: `MemAvailable` or `MemTotal`.
    pub source: &'static str,
}

impl fmt::Display for MachineMemory {
    /// `3.2 GB available (MemAvailable in /proc/meminfo)`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let what = if self.source == "MemAvailable" { "available" } else { "in all" };
        write!(f, "{} {what} ({} in /proc/meminfo)", gigabytes(self.bytes), self.source)
    }
}

/// The machine's memory as [`MachineMemory`] (module docs); `None` where the OS does not say.
pub fn machine_memory() -> Option<MachineMemory> {
    parse_meminfo(&std::fs::read_to_string("/proc/meminfo").ok()?)
}

/// `MemAvailable`, else `MemTotal`, of the text of `/proc/meminfo`.
fn parse_meminfo(text: &str) -> Option<MachineMemory> {
    let field = |name: &str| -> Option<u128> {
        let line = text.lines().find(|l| l.split(':').next() == Some(name))?;
        let kb: u128 = line.split_whitespace().nth(1)?.parse().ok()?;
        Some(kb * 1024)
    };
    let (bytes, source) = match field("MemAvailable") {
        Some(b) => (b, "MemAvailable"),
        None => (field("MemTotal")?, "MemTotal"),
    };
    Some(MachineMemory { bytes, source })
}

/// `bytes` in GB with one decimal, or in MB or KB below a GB (`1.5 GB`, `21.3 KB`).
pub fn gigabytes(bytes: u128) -> String {
    let b = bytes as f64;
    if b >= 1e9 {
        format!("{:.1} GB", b / 1e9)
    } else if b >= 1e6 {
        format!("{:.1} MB", b / 1e6)
    } else {
        format!("{:.1} KB", b / 1e3)
    }
}

/// Checks that `bytes` (`None`: more than `u128` counts) fit in the machine's memory
/// ([`machine_memory`]); the error says `needs about X GB, more than this machine's Y GB
/// available (MemAvailable in /proc/meminfo)`. Passes where the OS does not say.
pub fn check_fits(bytes: Option<u128>) -> Result<(), String> {
    check_fits_in(bytes, machine_memory())
}

/// [`check_fits`] against `memory`.
pub fn check_fits_in(bytes: Option<u128>, memory: Option<MachineMemory>) -> Result<(), String> {
    let limit = memory.map_or(usize::MAX as u128, |m| m.bytes.min(usize::MAX as u128));
    match (bytes, memory) {
        (Some(b), _) if b <= limit => Ok(()),
        (Some(b), Some(m)) => Err(format!("needs about {}, more than this machine's {m}", gigabytes(b))),
        (Some(_), None) | (None, _) => Err("needs more memory than can be addressed".into()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn meminfo_gives_available_else_total_and_messages_say_which() {
        let text = "MemTotal:       16000000 kB\nMemFree:  1000 kB\nMemAvailable:    8000000 kB\n";
        let m = parse_meminfo(text).unwrap();
        assert_eq!((m.bytes, m.source), (8_192_000_000, "MemAvailable"));
        let old = parse_meminfo("MemTotal:       16000000 kB\nMemFree:  1000 kB\n").unwrap();
        assert_eq!((old.bytes, old.source), (16_384_000_000, "MemTotal"));
        assert!(parse_meminfo("nothing").is_none());
        check_fits_in(Some(1 << 20), Some(m)).unwrap();
        let e = check_fits_in(Some(21_000_000_000), Some(m)).unwrap_err();
        assert_eq!(e, "needs about 21.0 GB, more than this machine's 8.2 GB available (MemAvailable in /proc/meminfo)");
        let e = check_fits_in(Some(21_000_000_000), Some(old)).unwrap_err();
        assert!(e.ends_with("16.4 GB in all (MemTotal in /proc/meminfo)"), "{e}");
        assert!(check_fits_in(None, Some(m)).is_err());
        check_fits_in(Some(1 << 60), None).unwrap();
        assert_eq!(gigabytes(21_300), "21.3 KB");
    }
}
