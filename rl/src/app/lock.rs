//! The exclusive lock of a run directory: one training at a time writes a run.
//!
//! The lock is an OS advisory lock (`flock` on Unix, `LockFileEx` on Windows, through std's
//! [`std::fs::File::try_lock`]) on the file `lock` in the run directory, which holds the
//! holder's process id and host name for the message a second process gets. The OS
//! releases the lock when the holder exits, however it exits (kill -9 included), so a lock
//! left by a dead process never blocks: the file stays, its lock does not.

use std::fs::{File, OpenOptions, TryLockError};
use std::io::{Read, Seek, Write};
use std::path::{Path, PathBuf};

use crate::error::{Result, RlError};

/// The name of the lock file in a run directory.
pub const LOCK_FILE: &str = "lock";

/// A held lock on a run directory; dropping it releases the lock.
#[derive(Debug)]
pub struct RunLock {
    _file: File,
    path: PathBuf,
}

impl RunLock {
    /// Takes the lock of the run directory `root` (which must exist), or fails at once
    /// naming the holder (process id and host) if another process holds it
    /// ([`RlError::RunInUse`]).
    pub fn acquire(root: &Path) -> Result<RunLock> {
        let path = root.join(LOCK_FILE);
        let io = |what: &str, e: std::io::Error| RlError::file(&path, format!("cannot {what} the lock file: {e}"));
        let mut file = OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(&path)
            .map_err(|e| io("open", e))?;
        match file.try_lock() {
            Ok(()) => {}
            Err(TryLockError::WouldBlock) => {
                let holder = read_holder(&mut file);
                return Err(RlError::RunInUse { run: root.to_path_buf(), lock: path, holder });
            }
            Err(TryLockError::Error(e)) => return Err(io("lock", e)),
        }
        let holder = format!("process {} on host {}\n", std::process::id(), host_name());
        file.set_len(0).map_err(|e| io("write", e))?;
        file.rewind().map_err(|e| io("write", e))?;
        file.write_all(holder.as_bytes()).map_err(|e| io("write", e))?;
        Ok(RunLock { _file: file, path })
    }

    /// The lock file.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

/// The holder a lock file names (`another process` if it names none).
fn read_holder(file: &mut File) -> String {
    let mut holder = String::new();
    let _ = file.read_to_string(&mut holder);
    let holder = holder.trim();
    if holder.is_empty() { "another process".to_string() } else { holder.to_string() }
}

/// The holder of the run directory `root`'s lock as its lock file names it, if a process
/// holds the lock now; `None` if none does or there is no lock file. It writes nothing: it
/// tries a shared lock on the file and, given it, lets it go at once (a training that
/// starts in that instant is refused as by any holder).
pub fn holder(root: &Path) -> Result<Option<String>> {
    let path = root.join(LOCK_FILE);
    let mut file = match File::open(&path) {
        Ok(f) => f,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(RlError::file(&path, format!("cannot open the lock file: {e}"))),
    };
    match file.try_lock_shared() {
        Ok(()) => {
            let _ = file.unlock();
            Ok(None)
        }
        Err(TryLockError::WouldBlock) => Ok(Some(read_holder(&mut file))),
        Err(TryLockError::Error(e)) => Err(RlError::file(&path, format!("cannot lock the lock file: {e}"))),
    }
}

/// This machine's name, as the kernel reports it (`unknown` where it cannot be read).
fn host_name() -> String {
    ["/proc/sys/kernel/hostname", "/etc/hostname"]
        .iter()
        .find_map(|p| std::fs::read_to_string(p).ok().map(|s| s.trim().to_string()).filter(|s| !s.is_empty()))
        .or_else(|| std::env::var("COMPUTERNAME").ok())
        .unwrap_or_else(|| "unknown".into())
}

/// Removes the temporary files of interrupted atomic writes ([`nn::is_temporary`]: the
/// `.<name>.<pid>.<n>.tmp` of every file, a checkpoint's tensors file's included) from a
/// run directory whose lock the caller holds (no other process can be writing them), and
/// the checkpoint tensors files (`checkpoint.<digest>.safetensors`) that its
/// `checkpoint.json` does not name, which a crash between a save's steps leaves
/// ([`crate::mappo::checkpoint::remove_stale_tensor_files`]).
///
/// Training calls it only once the run's checkpoint has loaded and passed its checks
/// ([`crate::app::run::train`]): a `checkpoint.json` put back from an older save names a
/// tensors file that is gone, and cleaning up before the load failed removed the newer
/// pair's tensors file, the only good one (issue 77 item 2). A resume that fails changes
/// nothing.
pub fn remove_stale_temporaries(root: &Path, _lock: &RunLock) -> Result<()> {
    let entries = std::fs::read_dir(root).map_err(|e| RlError::file(root, format!("cannot list: {e}")))?;
    for entry in entries.flatten() {
        let name = entry.file_name();
        if nn::is_temporary(&name.to_string_lossy()) && entry.file_type().is_ok_and(|t| t.is_file()) {
            std::fs::remove_file(entry.path())
                .map_err(|e| RlError::file(entry.path(), format!("cannot remove a stale temporary file: {e}")))?;
        }
    }
    crate::mappo::checkpoint::remove_stale_tensor_files(&crate::app::run_dir::RunDir::new(root).checkpoint())?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_second_holder_is_refused_with_the_first_ones_name_until_it_lets_go() {
        let dir = std::env::temp_dir().join(format!("meben-lock-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let first = RunLock::acquire(&dir).unwrap();
        let e = RunLock::acquire(&dir).unwrap_err().to_string();
        assert!(e.contains(&format!("process {} on host", std::process::id())) && e.contains("in use"), "{e}");
        std::fs::write(dir.join(".checkpoint.json.77.0.tmp"), "half").unwrap();
        std::fs::write(dir.join(".checkpoint.0123456789abcdef.safetensors.77.1.tmp"), "half").unwrap();
        std::fs::write(dir.join("config.toml.tmp"), "").unwrap();
        // A tensors file without the checkpoint.json that would name it (a first save that
        // crashed between its two files); other safetensors files are not the run's.
        std::fs::write(dir.join("checkpoint.0123456789abcdef.safetensors"), "orphan").unwrap();
        std::fs::write(dir.join("policy.safetensors"), "mine").unwrap();
        remove_stale_temporaries(&dir, &first).unwrap();
        let mut left: Vec<String> =
            std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
        left.sort();
        assert_eq!(left, [LOCK_FILE, "policy.safetensors"]);
        drop(first);
        RunLock::acquire(&dir).unwrap();
        let _ = std::fs::remove_dir_all(&dir);
    }
}
