//! Allocation limits: a buffer sized from a configuration is checked against the machine's
//! memory before it is allocated, so an impossible size is a clear error naming the field
//! instead of an abort in the allocator.

/// The machine's physical memory in bytes (`MemTotal` of `/proc/meminfo`), where the OS
/// says; `None` elsewhere.
pub fn physical_memory() -> Option<u128> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemTotal:"))?;
    let kb: u128 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

/// Checks that `bytes` (`None`: more than `usize` can count) fit in this machine's memory;
/// the error gives the size in GB and the machine's memory.
pub fn check_fits_in_memory(bytes: Option<u128>) -> Result<(), String> {
    let limit = physical_memory().unwrap_or(usize::MAX as u128).min(usize::MAX as u128);
    match bytes {
        Some(b) if b <= limit => Ok(()),
        Some(b) => Err(format!(
            "needs {:.1} GB, more than this machine's {:.1} GB of memory",
            b as f64 / 1e9,
            limit as f64 / 1e9
        )),
        None => Err("needs more memory than can be addressed".into()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_beyond_the_machine_are_refused() {
        check_fits_in_memory(Some(1 << 20)).unwrap();
        let e = check_fits_in_memory(Some(1 << 100)).unwrap_err();
        assert!(e.contains("GB"), "{e}");
        assert!(check_fits_in_memory(None).is_err());
    }
}
