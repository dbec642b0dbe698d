//! Writing a folder completely or not at all: every output folder of the tools (datasets, model
//! folders, reports) is filled under a temporary sibling name and renamed into place only once
//! it is complete, so an interrupted or failed write never leaves a half-written folder.
//!
//! A process killed in the middle of a write (SIGKILL, power loss) cannot clean up: it may leave
//! its temporary folder `.NAME.tmp-PID-N`, and, if it died between moving the previous folder
//! aside and renaming the new one in, the previous folder as `.NAME.old-PID-N` with no `NAME`.
//! The next write of `NAME` repairs this first: a backup whose writer is gone is renamed back to
//! `NAME` when `NAME` is absent (the user's previous folder is never lost), and leftovers of
//! writers that are gone are removed. Whether a writer is gone is known from `/proc` (Linux);
//! elsewhere leftovers are only reported by their hidden names.

use std::fs;
use std::io::ErrorKind;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// Distinguishes concurrent writes of one process.
static WRITE_COUNTER: AtomicU64 = AtomicU64::new(0);

/// Why a folder could not be written.
#[derive(Debug, thiserror::Error)]
pub enum FolderError {
    /// The destination exists and is not a folder this tool wrote: it is never replaced.
    #[error("{path}: refusing to replace {found}")]
    Refused {
        /// The destination.
        path: PathBuf,
        /// What is there.
        found: &'static str,
    },
    /// A file-system operation failed.
    #[error("{path}: {action}: {source}")]
    Io {
        /// The path.
        path: PathBuf,
        /// What was being done.
        action: &'static str,
        /// The I/O error.
        source: std::io::Error,
    },
}

impl FolderError {
    fn io(path: &Path, action: &'static str) -> impl FnOnce(std::io::Error) -> Self {
        let path = path.to_path_buf();
        move |source| Self::Io { path, action, source }
    }
}

/// Writes the folder `dir` through `fill`, which receives the temporary folder to fill.
///
/// An existing `dir` is replaced only if it is empty or contains `marker` (the file that makes
/// it one of ours, e.g. `manifest.toml`), and only once the new folder is complete: it is moved
/// to a backup, the new folder renamed in, the backup removed. On any error the temporary folder
/// is removed and an existing `dir` is left as it was.
pub fn write_folder<E: From<FolderError>>(
    dir: &Path,
    marker: &str,
    fill: impl FnOnce(&Path) -> Result<(), E>,
) -> Result<(), E> {
    let (parent, name) = split(dir)?;
    recover_leftovers(parent, &name, dir);
    check_destination(dir, marker)?;
    if !parent.as_os_str().is_empty() {
        fs::create_dir_all(parent).map_err(FolderError::io(parent, "cannot create the folder"))?;
    }
    let id = format!("{}-{}", std::process::id(), WRITE_COUNTER.fetch_add(1, Ordering::Relaxed));
    let tmp = parent.join(format!(".{name}.tmp-{id}"));
    fs::create_dir(&tmp).map_err(FolderError::io(&tmp, "cannot create the temporary folder"))?;
    if let Err(err) = fill(&tmp) {
        // Best effort: the error that matters is the one that made the write fail.
        let _ = fs::remove_dir_all(&tmp);
        return Err(err);
    }
    move_into_place(&tmp, dir, &parent.join(format!(".{name}.old-{id}"))).map_err(E::from)
}

/// Restores the backup of an interrupted replacement and removes the leftovers of writers of
/// `name` in `parent` that are gone. Best effort: a leftover that cannot be removed only costs
/// disk space and never blocks the write.
fn recover_leftovers(parent: &Path, name: &str, dir: &Path) {
    let listing = if parent.as_os_str().is_empty() { Path::new(".") } else { parent };
    let Ok(entries) = fs::read_dir(listing) else {
        return;
    };
    let mut leftovers: Vec<(PathBuf, bool)> = entries
        .filter_map(Result::ok)
        .filter_map(|entry| {
            let file_name = entry.file_name();
            let rest = file_name.to_str()?.strip_prefix('.')?.strip_prefix(name)?;
            let (is_backup, id) = match rest.strip_prefix(".old-") {
                Some(id) => (true, id),
                None => (false, rest.strip_prefix(".tmp-")?),
            };
            let pid: u32 = id.split('-').next()?.parse().ok()?;
            writer_is_gone(pid).then(|| (parent.join(&file_name), is_backup))
        })
        .collect();
    // Backups first, so that a restored folder is not then taken for a leftover.
    leftovers.sort_by_key(|(_, is_backup)| !is_backup);
    for (path, is_backup) in leftovers {
        if is_backup && !dir.exists() && fs::rename(&path, dir).is_ok() {
            continue;
        }
        let _ = fs::remove_dir_all(&path);
    }
}

/// True when process `pid` has certainly ended (Linux `/proc`); false when unknown.
fn writer_is_gone(pid: u32) -> bool {
    pid != std::process::id() && Path::new("/proc/self").exists() && !Path::new("/proc").join(pid.to_string()).exists()
}

fn check_destination(dir: &Path, marker: &str) -> Result<(), FolderError> {
    let refuse = |found| Err(FolderError::Refused { path: dir.to_path_buf(), found });
    match fs::metadata(dir) {
        // Absent, or under a file: creating the parent folders reports the latter.
        Err(err) if matches!(err.kind(), ErrorKind::NotFound | ErrorKind::NotADirectory) => Ok(()),
        Err(err) => Err(FolderError::io(dir, "cannot inspect the destination")(err)),
        Ok(meta) if !meta.is_dir() => refuse("a file"),
        Ok(_) if dir.join(marker).is_file() => Ok(()),
        Ok(_) => {
            let mut entries = fs::read_dir(dir).map_err(FolderError::io(dir, "cannot list the folder"))?;
            if entries.next().is_none() { Ok(()) } else { refuse("a non-empty folder this tool did not write") }
        }
    }
}

/// The parent folder and the name of `dir`.
fn split(dir: &Path) -> Result<(&Path, String), FolderError> {
    let name = dir.file_name().and_then(|name| name.to_str()).ok_or_else(|| FolderError::Io {
        path: dir.to_path_buf(),
        action: "cannot write a folder here",
        source: std::io::Error::new(ErrorKind::InvalidInput, "expected a path ending in a folder name in UTF-8"),
    })?;
    Ok((dir.parent().unwrap_or_else(|| Path::new("")), name.to_owned()))
}

/// Renames the complete folder `tmp` to `dir`, moving an existing `dir` to `backup` first and
/// removing it afterwards.
fn move_into_place(tmp: &Path, dir: &Path, backup: &Path) -> Result<(), FolderError> {
    let existed = dir.exists();
    if existed && let Err(err) = fs::rename(dir, backup) {
        let _ = fs::remove_dir_all(tmp);
        return Err(FolderError::io(dir, "cannot move the previous folder aside")(err));
    }
    if let Err(err) = fs::rename(tmp, dir) {
        // Best effort: put the previous folder back and drop the new one.
        if existed {
            let _ = fs::rename(backup, dir);
        }
        let _ = fs::remove_dir_all(tmp);
        return Err(FolderError::io(tmp, "cannot rename the new folder into place")(err));
    }
    if existed {
        // The new folder is complete and in place; a backup that cannot be removed only costs
        // disk space, so it does not fail the write.
        let _ = fs::remove_dir_all(backup);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn split_refuses_paths_without_a_name() {
        let msg = split(Path::new("/")).unwrap_err().to_string();
        assert!(msg.starts_with("/: cannot write a folder here"), "{msg}");
        let dir = std::env::temp_dir().join("x");
        let (parent, name) = split(&dir).unwrap();
        assert_eq!((parent, name.as_str()), (std::env::temp_dir().as_path(), "x"));
    }

    #[test]
    fn failed_fill_leaves_nothing_and_keeps_the_old_folder() {
        let root = tempfile::tempdir().unwrap();
        let dir = root.path().join("out");
        write_folder::<FolderError>(&dir, "mark", |tmp| {
            fs::write(tmp.join("mark"), "1").map_err(FolderError::io(tmp, "write"))
        })
        .unwrap();
        let failed = write_folder::<FolderError>(&dir, "mark", |tmp| {
            fs::write(tmp.join("mark"), "2").map_err(FolderError::io(tmp, "write"))?;
            Err(FolderError::Refused { path: tmp.to_path_buf(), found: "a test failure" })
        });
        assert!(failed.is_err());
        assert_eq!(fs::read_to_string(dir.join("mark")).unwrap(), "1");
        let leftovers: Vec<_> = fs::read_dir(root.path()).unwrap().map(|entry| entry.unwrap().file_name()).collect();
        assert_eq!(leftovers, vec![std::ffi::OsString::from("out")]);
    }

    #[test]
    fn leftovers_of_a_killed_writer_are_repaired_by_the_next_write() {
        let root = tempfile::tempdir().unwrap();
        let dir = root.path().join("out");
        // A writer (pid 0x7fff_fff0, certainly not running) died between the two renames of a
        // replacement: its new folder half-filled, the previous folder only as the backup.
        let dead = 0x7fff_fff0u32;
        fs::create_dir(root.path().join(format!(".out.tmp-{dead}-0"))).unwrap();
        let backup = root.path().join(format!(".out.old-{dead}-0"));
        fs::create_dir(&backup).unwrap();
        fs::write(backup.join("mark"), "previous").unwrap();
        // The next write restores the previous folder, then replaces it as usual.
        let failed = write_folder::<FolderError>(&dir, "mark", |tmp| {
            Err(FolderError::Refused { path: tmp.to_path_buf(), found: "a test failure" })
        });
        assert!(failed.is_err());
        assert_eq!(fs::read_to_string(dir.join("mark")).unwrap(), "previous", "the user's folder is back");
        let leftovers: Vec<_> = fs::read_dir(root.path()).unwrap().map(|entry| entry.unwrap().file_name()).collect();
        assert_eq!(leftovers, vec![std::ffi::OsString::from("out")]);
    }

    #[test]
    fn foreign_folder_is_never_replaced() {
        let root = tempfile::tempdir().unwrap();
        fs::write(root.path().join("precious.txt"), "keep").unwrap();
        let refused = write_folder::<FolderError>(root.path(), "mark", |_| Ok(()));
        assert!(matches!(refused, Err(FolderError::Refused { .. })));
        assert!(root.path().join("precious.txt").is_file());
    }
}
