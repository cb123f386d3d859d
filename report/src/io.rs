//! Atomic file output.

use crate::ReportError;
use std::fs::{self, File, OpenOptions};
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

static COUNTER: AtomicU64 = AtomicU64::new(0);

/// Writes `contents` to `path` atomically: the bytes go to a new temporary file
/// `.<name>.<pid>.<n>.tmp` in the same directory, are flushed to disk (`fsync`), and the file is
/// then renamed over `path` (POSIX `rename(2)` replaces the target in one step, so a reader sees
/// either the old file or the complete new one, never a partial one). The temporary file is removed
/// if any step fails. The directory must exist.
pub fn write_atomic(path: impl AsRef<Path>, contents: impl AsRef<[u8]>) -> Result<(), ReportError> {
    let path: &Path = path.as_ref();
    let io_error = |e: std::io::Error| ReportError::Io { path: path.display().to_string(), message: e.to_string() };
    let name: &str = match path.file_name().and_then(|n| n.to_str()) {
        Some(n) => n,
        None => {
            return Err(ReportError::Io {
                path: path.display().to_string(),
                message: "expected a path ending in a (UTF-8) file name".to_string(),
            })
        }
    };
    let dir: &Path = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let n: u64 = COUNTER.fetch_add(1, Ordering::Relaxed);
    let tmp: PathBuf = dir.join(format!(".{name}.{}.{n}.tmp", std::process::id()));
    let result: std::io::Result<()> = (|| {
        let mut file: File = OpenOptions::new().write(true).create_new(true).open(&tmp)?;
        file.write_all(contents.as_ref())?;
        file.sync_all()?;
        drop(file);
        fs::rename(&tmp, path)
    })();
    if let Err(e) = result {
        let _ = fs::remove_file(&tmp);
        return Err(io_error(e));
    }
    Ok(())
}
