//! Reading a file with a bound on its size (issue 77 item 8): a policy file, a checkpoint,
//! its tensors file or the paper's figures given `/dev/zero` used to be read until memory
//! ran out, and a FIFO hung the program. [`read_bytes`] refuses anything but a regular file
//! before opening it, refuses a file whose size is above the bound before reading it, and
//! reads at most one byte past the bound (a file that grows while it is read), each time
//! with an error naming the file and the bound.

use std::io::Read;
use std::path::Path;

use crate::error::{Result, RlError};

/// The bytes of the regular file `path`, at most `max_bytes` of them (module docs); `what`
/// says what the file was expected to be (`a policy file`), for the errors.
pub fn read_bytes(path: &Path, max_bytes: u64, what: &str) -> Result<Vec<u8>> {
    let meta = std::fs::metadata(path).map_err(|e| RlError::file(path, format!("cannot read {what}: {e}")))?;
    if !meta.is_file() {
        let kind = if meta.is_dir() { "a directory" } else { "not a regular file (a device, FIFO or socket)" };
        return Err(RlError::file(path, format!("{kind}: {what} must be a regular file")));
    }
    let too_large = || {
        let mib = max_bytes as f64 / f64::from(1u32 << 20);
        RlError::file(path, format!("larger than {max_bytes} bytes ({mib} MiB): too large for {what}"))
    };
    if meta.len() > max_bytes {
        return Err(too_large());
    }
    let file = std::fs::File::open(path).map_err(|e| RlError::file(path, format!("cannot read {what}: {e}")))?;
    let mut bytes = Vec::with_capacity(meta.len() as usize);
    file.take(max_bytes + 1)
        .read_to_end(&mut bytes)
        .map_err(|e| RlError::file(path, format!("cannot read {what}: {e}")))?;
    if bytes.len() as u64 > max_bytes {
        return Err(too_large());
    }
    Ok(bytes)
}

/// [`read_bytes`] as UTF-8 text.
pub fn read_text(path: &Path, max_bytes: u64, what: &str) -> Result<String> {
    let bytes = read_bytes(path, max_bytes, what)?;
    String::from_utf8(bytes).map_err(|e| RlError::file(path, format!("cannot read {what}: not UTF-8 text ({e})")))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn devices_directories_and_large_files_are_refused_naming_the_file_and_the_bound() {
        let dir = std::env::temp_dir().join(format!("meben-bounded-read-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join("f.bin");
        std::fs::write(&file, [7u8; 100]).unwrap();
        assert_eq!(read_bytes(&file, 100, "a test file").unwrap(), [7u8; 100]);
        let e = read_bytes(&file, 99, "a test file").unwrap_err().to_string();
        assert!(e.contains("f.bin") && e.contains("larger than 99 bytes") && e.contains("a test file"), "{e}");
        let e = read_bytes(Path::new("/dev/zero"), 1 << 20, "a policy file").unwrap_err().to_string();
        assert!(e.contains("/dev/zero") && e.contains("not a regular file") && e.contains("a policy file"), "{e}");
        let e = read_bytes(&dir, 1 << 20, "a policy file").unwrap_err().to_string();
        assert!(e.contains("a directory"), "{e}");
        let e = read_bytes(&dir.join("missing"), 1, "a policy file").unwrap_err().to_string();
        assert!(e.contains("missing") && e.contains("cannot read a policy file"), "{e}");
        std::fs::write(&file, [0xff, 0xfe]).unwrap();
        assert!(read_text(&file, 10, "a test file").unwrap_err().to_string().contains("not UTF-8"));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
