//! Checked file access. Inputs: a FIFO, `/dev/zero` or a directory named where a file is read
//! would block forever or read without end, so inputs must be regular files.
//! Writes: `std::fs::write` reports a failed `write`, but a full disk can also show
//! up only when the data reaches the device (delayed allocation, network file systems), and a
//! writer dropped without `flush` drops its error. Every output (EXR, PNG, VDB, grids) is
//! encoded in memory and written here, so ENOSPC (`/dev/full`), a missing folder or a denied
//! permission is an `Error::Io` naming the path, never a silent success.
//! [`write_file_atomic`] also leaves the path either as it was or wholly new: a temporary
//! beside it, then a rename.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

use crate::error::{Error, Result};

/// Writes `bytes` to `path` (created or truncated) and waits for the device to accept them.
pub fn write_file(path: &Path, bytes: &[u8]) -> Result<()> {
    let mut file = std::fs::File::create(path).map_err(|e| Error::io(path, e))?;
    file.write_all(bytes).map_err(|e| Error::io(path, e))?;
    file.flush().map_err(|e| Error::io(path, e))?;
    // Regular files only: fsync on a character device (/dev/null, /dev/full) is EINVAL, which
    // says nothing about whether the bytes were taken.
    if file.metadata().map(|m| m.is_file()).unwrap_or(false) {
        file.sync_data().map_err(|e| Error::io(path, e))?;
    }
    Ok(())
}

/// Writes `bytes` to a temporary file beside `path` ([`temp_beside`]) and renames it over
/// `path`: `path` is either the old file or the whole new one. On any failure the temporary
/// is removed and the error names the file at fault.
/// A path that is a device or a FIFO (`/dev/null`, `/dev/full`, a pipe) is written in place: a
/// rename would replace the device with a file. A symbolic link's target is replaced, not the
/// link.
pub fn write_file_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let target = match std::fs::symlink_metadata(path) {
        Ok(m) if m.file_type().is_symlink() => std::fs::canonicalize(path).unwrap_or_else(|_| path.to_path_buf()),
        _ => path.to_path_buf(),
    };
    if std::fs::metadata(&target).is_ok_and(|m| !m.is_file() && !m.is_dir()) {
        return write_file(&target, bytes);
    }
    let path = target.as_path();
    let tmp = temp_beside(path);
    let res = write_file(&tmp, bytes).and_then(|()| std::fs::rename(&tmp, path).map_err(|e| Error::io(path, e)));
    if res.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    // The error names the file the caller asked for, not the temporary.
    res.map_err(|e| match e {
        Error::Io { source, .. } => Error::io(path, source),
        other => other,
    })
}

/// A fresh name for a temporary file beside `path` (same folder, so that a rename replaces
/// `path` without crossing file systems): `.<file name>.<process id>-<n>.tmp`.
pub fn temp_beside(path: &Path) -> PathBuf {
    static N: AtomicUsize = AtomicUsize::new(0);
    let n = N.fetch_add(1, Ordering::Relaxed);
    let name = path.file_name().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    path.with_file_name(format!(".{name}.{}-{n}.tmp", std::process::id()))
}

/// The size of `path`, which must be a regular file (`what` names it in the message).
pub fn regular_file(path: &Path, what: &str) -> Result<u64> {
    let meta = std::fs::metadata(path).map_err(|e| Error::io(path, e))?;
    if !meta.is_file() {
        return Err(Error::io(path, std::io::Error::new(std::io::ErrorKind::InvalidInput, format!("{what} is not a regular file"))));
    }
    Ok(meta.len())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn non_regular_inputs_are_refused_without_reading() {
        let e = regular_file(&std::env::temp_dir(), "medium").unwrap_err();
        assert!(matches!(e, Error::Io { .. }) && e.to_string().contains("not a regular file"), "{e}");
        if Path::new("/dev/zero").exists() {
            assert!(regular_file(Path::new("/dev/zero"), "medium").is_err());
        }
    }

    #[test]
    fn full_disk_and_missing_folder_are_io_errors() {
        if Path::new("/dev/full").exists() {
            match write_file(Path::new("/dev/full"), &[0u8; 4096]) {
                Err(Error::Io { source, .. }) => assert_eq!(source.raw_os_error(), Some(28), "ENOSPC expected: {source}"),
                other => panic!("/dev/full must fail with ENOSPC, got {other:?}"),
            }
        } else {
            eprintln!("skipped: /dev/full does not exist on this system");
        }
        let missing = std::env::temp_dir().join(format!("vs-no-such-dir-{}", std::process::id())).join("out.exr");
        let e = write_file(&missing, b"x").unwrap_err();
        assert!(matches!(&e, Error::Io { source, .. } if source.kind() == std::io::ErrorKind::NotFound), "{e:?}");
        assert!(e.to_string().contains("out.exr"), "{e}");
        let e = write_file_atomic(&missing, b"x").unwrap_err();
        assert!(matches!(&e, Error::Io { path, .. } if path == &missing), "the error names the target: {e:?}");
    }

    #[test]
    fn atomic_write_replaces_whole_or_leaves_the_file() {
        let dir = std::env::temp_dir().join(format!("vs-atomic-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("a.bin");
        write_file_atomic(&path, b"old").unwrap();
        write_file_atomic(&path, b"new").unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"new");
        // A rename that fails (onto a non-empty directory) leaves neither a temporary nor a change.
        let sub = dir.join("sub");
        std::fs::create_dir_all(sub.join("x")).unwrap();
        assert!(matches!(write_file_atomic(&sub, b"x"), Err(Error::Io { .. })));
        let names: Vec<_> = std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert_eq!(names.len(), 2, "{names:?}");
        assert!(sub.join("x").is_dir());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn atomic_write_keeps_devices_and_links() {
        // A device is written in place (a rename would put a file where /dev/full was).
        if Path::new("/dev/full").exists() {
            assert!(matches!(write_file_atomic(Path::new("/dev/full"), b"x"), Err(Error::Io { .. })));
            assert!(!std::fs::metadata("/dev/full").unwrap().is_file(), "/dev/full must stay a device");
        } else {
            eprintln!("skipped the /dev/full half: /dev/full does not exist on this system");
        }
        #[cfg(unix)]
        {
            let dir = std::env::temp_dir().join(format!("vs-atomic-link-{}", std::process::id()));
            std::fs::create_dir_all(&dir).unwrap();
            let (target, link) = (dir.join("target.bin"), dir.join("link.bin"));
            std::fs::write(&target, b"old").unwrap();
            std::os::unix::fs::symlink(&target, &link).unwrap();
            write_file_atomic(&link, b"new").unwrap();
            assert!(std::fs::symlink_metadata(&link).unwrap().file_type().is_symlink(), "the link stays a link");
            assert_eq!(std::fs::read(&target).unwrap(), b"new");
            std::fs::remove_dir_all(&dir).unwrap();
        }
    }
}
