//! One output transaction per command (DESIGN.md §2, issue 14): everything a command writes goes into
//! a temporary directory beside the destination, `NAME.vmt-partial-PID`, and is swapped in once after
//! all work, so the destination holds either the complete old outputs or the complete new ones: never
//! a mix, never nothing.
//!
//! - The destination is replaced only if it is empty or holds `.vmt-output`, the list of files vmt
//!   wrote there, and nothing else: vmt never deletes or overwrites a file it did not write.
//! - The swap is one `renameat2(RENAME_EXCHANGE)` on Linux (the destination is never absent); where
//!   the file system lacks it, two renames (the old output is absent for the instant between them,
//!   kept as `NAME.vmt-partial-PID` meanwhile).
//! - Leftovers of an interrupted command are named `NAME.vmt-partial-PID` (visible, beside the
//!   destination) and removed by the next command writing to the same destination; only directories
//!   holding vmt's own marker (`.vmt-partial` or `.vmt-output`) are removed.

use crate::error::VmtError;
use std::path::{Path, PathBuf};

/// The file in an output directory listing what vmt wrote there (one relative path per line).
pub const OUTPUT_MARKER: &str = ".vmt-output";
/// The file marking a temporary directory as vmt's own while it is being filled.
const PARTIAL_MARKER: &str = ".vmt-partial";
/// The tag of temporary directories: `NAME.vmt-partial-PID`.
const PARTIAL_TAG: &str = ".vmt-partial-";

/// The parent directory of `path` ("." for a bare name).
fn parent_dir(path: &Path) -> PathBuf {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    }
}

fn file_name(path: &Path) -> String {
    path.file_name().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| "out".to_string())
}

/// Every regular file under `dir`, as sorted relative paths with `/` separators.
fn list_files(dir: &Path) -> Result<Vec<String>, VmtError> {
    fn walk(root: &Path, dir: &Path, out: &mut Vec<String>) -> Result<(), VmtError> {
        for e in std::fs::read_dir(dir).map_err(|e| VmtError::io(dir, "reading the directory", e))? {
            let e = e.map_err(|e| VmtError::io(dir, "reading the directory", e))?;
            let p = e.path();
            let kind = e.file_type().map_err(|er| VmtError::io(&p, "reading the directory", er))?;
            if kind.is_dir() {
                walk(root, &p, out)?;
            } else {
                let rel = p.strip_prefix(root).unwrap_or(&p);
                out.push(rel.components().map(|c| c.as_os_str().to_string_lossy()).collect::<Vec<_>>().join("/"));
            }
        }
        Ok(())
    }
    let mut out = Vec::new();
    walk(dir, dir, &mut out)?;
    out.sort();
    Ok(out)
}

/// Checks that `dest` may be replaced: absent, an empty directory, or a previous vmt output holding
/// only the files its `.vmt-output` lists. Returns whether it exists.
fn check_replaceable(dest: &Path) -> Result<bool, VmtError> {
    match std::fs::symlink_metadata(dest) {
        Ok(m) if m.is_dir() => {}
        Ok(_) => return Err(VmtError::bad(dest, "", "expected an output directory, but a file of that name exists")),
        Err(_) => return Ok(false),
    }
    let files = list_files(dest)?;
    if files.is_empty() {
        return Ok(true);
    }
    let marker = dest.join(OUTPUT_MARKER);
    let listed: Vec<String> = match std::fs::read_to_string(&marker) {
        Ok(t) => t.lines().map(str::to_string).collect(),
        Err(_) => {
            return Err(VmtError::bad(
                dest,
                "",
                format!(
                    "refusing to replace this directory: it is not empty and holds no `{OUTPUT_MARKER}`, so vmt did \
                     not write it; choose another output path (or empty it)"
                ),
            ))
        }
    };
    if let Some(f) = files.iter().find(|f| f.as_str() != OUTPUT_MARKER && !listed.contains(f)) {
        return Err(VmtError::bad(
            dest,
            "",
            format!(
                "refusing to replace this directory: `{f}` is not one of the files vmt wrote there (listed in \
                 `{OUTPUT_MARKER}`); move it away or choose another output path"
            ),
        ));
    }
    Ok(true)
}

/// Checks, before a command does its work, that its output directory `dest` may be replaced (absent,
/// empty, or a previous vmt output holding only the files its `.vmt-output` lists), so that a refusal
/// comes at once and not after the simulation; [`replace_dir`] checks again just before it writes.
pub fn check_destination(dest: &Path) -> Result<(), VmtError> {
    check_replaceable(dest).map(|_| ())
}

/// Removes the leftovers `NAME.vmt-partial-*` of interrupted commands writing to `dest` (only
/// directories holding vmt's own markers, or empty ones).
fn clean_leftovers(dest: &Path) {
    let parent = parent_dir(dest);
    let prefix = format!("{}{PARTIAL_TAG}", file_name(dest));
    let Ok(entries) = std::fs::read_dir(&parent) else { return };
    for e in entries.flatten() {
        let p = e.path();
        // Ours: named by vmt and holding one of its markers, or empty (a run killed between creating
        // the directory and writing its marker; removing an empty directory deletes nothing).
        let empty = std::fs::read_dir(&p).is_ok_and(|mut d| d.next().is_none());
        let ours = e.file_name().to_string_lossy().starts_with(&prefix)
            && (empty || p.join(PARTIAL_MARKER).is_file() || p.join(OUTPUT_MARKER).is_file());
        if ours {
            remove_marked_dir(&p);
        }
    }
}

/// Removes a directory of vmt's (a leftover or a replaced output) with its markers last, so that a
/// kill during the removal leaves a directory the next run still recognises as its own.
fn remove_marked_dir(p: &Path) {
    if let Ok(entries) = std::fs::read_dir(p) {
        for e in entries.flatten() {
            let name = e.file_name();
            if name == PARTIAL_MARKER || name == OUTPUT_MARKER {
                continue;
            }
            let q = e.path();
            let _ = if q.is_dir() { std::fs::remove_dir_all(&q) } else { std::fs::remove_file(&q) };
        }
    }
    let _ = std::fs::remove_dir_all(p);
}

/// Atomically exchanges two directories (Linux `renameat2(RENAME_EXCHANGE)`); false where the
/// system or file system does not support it.
#[cfg(target_os = "linux")]
fn exchange(a: &Path, b: &Path) -> std::io::Result<bool> {
    use std::os::unix::ffi::OsStrExt;
    let ca = std::ffi::CString::new(a.as_os_str().as_bytes()).map_err(std::io::Error::other)?;
    let cb = std::ffi::CString::new(b.as_os_str().as_bytes()).map_err(std::io::Error::other)?;
    // SAFETY: two valid NUL-terminated paths, relative to the current directory.
    let r = unsafe { libc::renameat2(libc::AT_FDCWD, ca.as_ptr(), libc::AT_FDCWD, cb.as_ptr(), libc::RENAME_EXCHANGE) };
    if r == 0 {
        return Ok(true);
    }
    let e = std::io::Error::last_os_error();
    match e.raw_os_error() {
        Some(libc::EINVAL) | Some(libc::ENOSYS) | Some(libc::EOPNOTSUPP) => Ok(false),
        _ => Err(e),
    }
}

#[cfg(not(target_os = "linux"))]
fn exchange(_a: &Path, _b: &Path) -> std::io::Result<bool> {
    Ok(false)
}

/// Runs one output transaction on the directory `dest`: checks it may be replaced, removes
/// leftovers of interrupted runs, lets `fill` write everything into a fresh temporary directory,
/// lists the files in `.vmt-output`, and swaps the result in. `fill` should only write: do the work
/// (simulation, estimators) before calling this, so that the swap follows it immediately.
pub fn replace_dir(dest: &Path, fill: impl FnOnce(&Path) -> Result<(), VmtError>) -> Result<(), VmtError> {
    let exists = check_replaceable(dest)?;
    let parent = parent_dir(dest);
    std::fs::create_dir_all(&parent).map_err(|e| VmtError::io(&parent, "creating the directory", e))?;
    clean_leftovers(dest);
    let tmp = parent.join(format!("{}{PARTIAL_TAG}{}", file_name(dest), std::process::id()));
    if tmp.exists() {
        remove_marked_dir(&tmp);
    }
    std::fs::create_dir(&tmp).map_err(|e| VmtError::io(&tmp, "creating the directory", e))?;
    let result = (|| {
        std::fs::write(tmp.join(PARTIAL_MARKER), b"").map_err(|e| VmtError::io(&tmp, "writing", e))?;
        fill(&tmp)?;
        // The output marker is written before the partial marker goes, so a kill at any instant
        // leaves a directory that holds one of vmt's markers (or, right after `create_dir`, nothing).
        let mut list = list_files(&tmp)?.into_iter().filter(|f| f != PARTIAL_MARKER).collect::<Vec<_>>().join("\n");
        list.push('\n');
        let marker = tmp.join(OUTPUT_MARKER);
        std::fs::write(&marker, list).map_err(|e| VmtError::io(&marker, "writing", e))?;
        std::fs::remove_file(tmp.join(PARTIAL_MARKER)).map_err(|e| VmtError::io(&tmp, "writing", e))?;
        sync_dir(&tmp);
        if exists {
            let swapped = exchange(&tmp, dest).map_err(|e| VmtError::io(dest, "swapping the new output in", e))?;
            if !swapped {
                let old = parent.join(format!("{}{PARTIAL_TAG}{}-old", file_name(dest), std::process::id()));
                std::fs::rename(dest, &old).map_err(|e| VmtError::io(dest, "moving the old output aside", e))?;
                if let Err(e) = std::fs::rename(&tmp, dest) {
                    let _ = std::fs::rename(&old, dest);
                    return Err(VmtError::io(dest, "renaming into place", e));
                }
                remove_marked_dir(&old);
                return Ok(());
            }
            // `tmp` now holds the old output.
            remove_marked_dir(&tmp);
            Ok(())
        } else {
            std::fs::rename(&tmp, dest).map_err(|e| VmtError::io(dest, "renaming into place", e))
        }
    })();
    if result.is_err() {
        remove_marked_dir(&tmp);
    }
    sync_dir(&parent);
    result
}

/// Flushes a directory's entries to disk (best effort).
fn sync_dir(dir: &Path) {
    if let Ok(f) = std::fs::File::open(dir) {
        let _ = f.sync_all();
    }
}

/// Refuses an output file that is one of the command's inputs, or a file of an input directory
/// (a measurement set), so that a command never overwrites what it reads.
pub fn refuse_input_overwrite(out: &Path, inputs: &[&Path]) -> Result<(), VmtError> {
    let canon = |p: &Path| -> Option<PathBuf> {
        std::fs::canonicalize(p).ok().or_else(|| {
            let parent = std::fs::canonicalize(parent_dir(p)).ok()?;
            Some(parent.join(p.file_name()?))
        })
    };
    let Some(o) = canon(out) else { return Ok(()) };
    for i in inputs {
        let Some(c) = canon(i) else { continue };
        if o == c || (c.is_dir() && o.starts_with(&c)) {
            return Err(VmtError::bad(
                out,
                "",
                format!("refusing to write over an input ({}): choose an output path outside it", i.display()),
            ));
        }
    }
    Ok(())
}
