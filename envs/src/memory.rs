//! The machine's memory, so that sizes it cannot hold are refused before they are
//! allocated (an error naming the size, not `memory allocation of N bytes failed` and an
//! aborted process).
//!
//! The bound is `MemAvailable` of `/proc/meminfo`: what the kernel says can be allocated now
//! without swapping (free memory plus caches it can drop). Where that line is missing (Linux
//! before 3.14) `MemTotal` is used, and where there is no `/proc/meminfo` (not Linux) nothing
//! is refused. The process's own limits (`ulimit -v`, `ulimit -d`, its control group's
//! memory limit: [`crate::memory_limits`]) bound it too: the smallest of them all is used.
//! Every message says which bound it used.

use std::fmt;

/// How much memory the machine offers, and where the figure comes from.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct MachineMemory {
    /// Bytes.
    pub bytes: u128,
    /// Where the figure comes from: the `/proc/meminfo` line (`MemAvailable` or `MemTotal`)
    /// or a process limit's description ([`crate::memory_limits::ProcessLimit::source`]).
    pub source: String,
}

impl MachineMemory {
    /// Whether the figure is the machine's (`/proc/meminfo`), not a limit of the process.
    pub fn is_machine(&self) -> bool {
        self.source == "MemAvailable" || self.source == "MemTotal"
    }
}

impl fmt::Display for MachineMemory {
    /// `3.2 GB available (MemAvailable in /proc/meminfo)`, or for a process limit `1.0 GB
    /// left (memory.max minus memory.current of /sys/fs/cgroup/x)`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if !self.is_machine() {
            return write!(f, "{} left ({})", gigabytes(self.bytes), self.source);
        }
        let what = if self.source == "MemAvailable" { "available" } else { "in all" };
        write!(f, "{} {what} ({} in /proc/meminfo)", gigabytes(self.bytes), self.source)
    }
}

/// The memory this process may allocate as [`MachineMemory`] (module docs): the smallest of
/// the machine's and the process's limits; `None` where the OS says nothing.
pub fn machine_memory() -> Option<MachineMemory> {
    let machine = std::fs::read_to_string("/proc/meminfo").ok().and_then(|t| parse_meminfo(&t));
    let limits =
        crate::memory_limits::process_limits().into_iter().map(|l| MachineMemory { bytes: l.bytes, source: l.source });
    smallest(machine.into_iter().chain(limits))
}

/// The smallest of `bounds` (the first of equals).
fn smallest(bounds: impl IntoIterator<Item = MachineMemory>) -> Option<MachineMemory> {
    bounds.into_iter().fold(None, |best: Option<MachineMemory>, m| match best {
        Some(b) if b.bytes <= m.bytes => Some(b),
        _ => Some(m),
    })
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
    Some(MachineMemory { bytes, source: source.into() })
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
    let limit = memory.as_ref().map_or(usize::MAX as u128, |m| m.bytes.min(usize::MAX as u128));
    match (bytes, memory) {
        (Some(b), _) if b <= limit => Ok(()),
        (Some(b), Some(m)) if m.is_machine() => {
            Err(format!("needs about {}, more than this machine's {m}", gigabytes(b)))
        }
        (Some(b), Some(m)) => Err(format!("needs about {}, more than this process's limit: {m}", gigabytes(b))),
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
        assert_eq!((m.bytes, m.source.as_str()), (8_192_000_000, "MemAvailable"));
        let old = parse_meminfo("MemTotal:       16000000 kB\nMemFree:  1000 kB\n").unwrap();
        assert_eq!((old.bytes, old.source.as_str()), (16_384_000_000, "MemTotal"));
        assert!(parse_meminfo("nothing").is_none());
        check_fits_in(Some(1 << 20), Some(m.clone())).unwrap();
        let e = check_fits_in(Some(21_000_000_000), Some(m.clone())).unwrap_err();
        assert_eq!(e, "needs about 21.0 GB, more than this machine's 8.2 GB available (MemAvailable in /proc/meminfo)");
        let e = check_fits_in(Some(21_000_000_000), Some(old.clone())).unwrap_err();
        assert!(e.ends_with("16.4 GB in all (MemTotal in /proc/meminfo)"), "{e}");
        assert!(check_fits_in(None, Some(m.clone())).is_err());
        check_fits_in(Some(1 << 60), None).unwrap();
        assert_eq!(gigabytes(21_300), "21.3 KB");
        // The smallest bound wins, and a process limit says so.
        let cgroup = MachineMemory {
            bytes: 2_000_000_000,
            source: "memory.max minus memory.current of /sys/fs/cgroup/x".into(),
        };
        assert_eq!(smallest([m.clone(), cgroup.clone(), old]), Some(cgroup.clone()));
        assert_eq!(smallest([]), None);
        let e = check_fits_in(Some(3_000_000_000), Some(cgroup)).unwrap_err();
        assert_eq!(
            e,
            "needs about 3.0 GB, more than this process's limit: 2.0 GB left (memory.max minus memory.current of \
             /sys/fs/cgroup/x)"
        );
    }
}
