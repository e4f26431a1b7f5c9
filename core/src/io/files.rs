//! Checked file access. Inputs: a FIFO, `/dev/zero` or a directory named where a file is read
//! would block forever or read without end, so inputs must be regular files.
//! Writes: `std::fs::write` reports a failed `write`, but a full disk can also show
//! up only when the data reaches the device (delayed allocation, network file systems), and a
//! writer dropped without `flush` drops its error. Every output (EXR, PNG, VDB, grids) is
//! encoded in memory and written here, so ENOSPC (`/dev/full`), a missing folder or a denied
//! permission is an `Error::Io` naming the path, never a silent success.

use std::io::Write;
use std::path::Path;

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
    }
}
