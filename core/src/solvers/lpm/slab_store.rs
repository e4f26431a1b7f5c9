//! A per-cell array on disk for the out-of-core solve (out_of_core.rs): `k` RGB values a cell,
//! cells x fastest, in a scratch file read and written box by box with positioned reads and
//! writes (std::fs only, no mmap: the page cache is the kernel's to drop, and a full disk is
//! an ordinary write error, not a SIGBUS).
//!
//! A box along any axis is a set of contiguous runs: a z-slab is one run, a y-slab one run a
//! plane, an x-slab one run a row; runs that touch are merged, so the whole-extent boxes of a
//! slab cost as few system calls as their layout allows.
//!
//! The file is created new (never an existing one), sized sparse (unwritten cells read as
//! zero: a fresh store is a zeroed array without writing it). On Unix its name is unlinked
//! right after it is opened, so that nothing is left behind whatever ends the process
//! (SIGKILL, a crash, the OOM killer): the space goes back when the descriptor closes.
//! Elsewhere it is removed when the store is dropped: on success, an error or a cancel.

use std::fs::{File, OpenOptions};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use glam::Vec3;

use crate::error::{Error, Result};

/// Bytes of one stored RGB value (three little-endian f32).
pub const VALUE_BYTES: usize = 12;

pub struct SlabStore {
    file: File,
    path: PathBuf,
    dims: [usize; 3],
    /// RGB values a cell.
    k: usize,
}

/// Numbers scratch files apart within a process (several solves may run at once).
static NEXT: AtomicU64 = AtomicU64::new(0);

impl SlabStore {
    /// A zeroed store of `dims` cells of `k` values in a new file in `dir`; `what` names it in
    /// the file name and in errors.
    pub fn create(dir: &Path, what: &str, dims: [usize; 3], k: usize) -> Result<Self> {
        let n = NEXT.fetch_add(1, Ordering::Relaxed);
        let path = dir.join(format!("volscatter-lpm-{}-{n}-{what}.bin", std::process::id()));
        let file = OpenOptions::new().read(true).write(true).create_new(true).open(&path).map_err(|e| {
            Error::io(&path, std::io::Error::new(e.kind(), format!("{e} (lpm out-of-core scratch file; set TMPDIR to an existing folder with room)")))
        })?;
        // Anonymous from here on (Unix): no name to leave behind.
        #[cfg(unix)]
        let _ = std::fs::remove_file(&path);
        let store = SlabStore { file, path, dims, k };
        let bytes = (dims.iter().product::<usize>() as u64) * (k * VALUE_BYTES) as u64;
        store.file.set_len(bytes).map_err(|e| store.error(e))?;
        Ok(store)
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Bytes the store takes on disk once written.
    pub fn bytes(&self) -> u64 {
        (self.dims.iter().product::<usize>() * self.k * VALUE_BYTES) as u64
    }

    fn error(&self, e: std::io::Error) -> Error {
        // ENOSPC and friends, with the file and a hint: the scratch directory is the caller's.
        Error::io(&self.path, std::io::Error::new(e.kind(), format!("{e} (lpm out-of-core scratch file; set TMPDIR or the scratch directory to a disk with room)")))
    }

    /// The contiguous runs (first cell, cells) of box `lo..hi`, in the box's own x-fastest
    /// order, touching runs merged.
    fn runs(&self, lo: [usize; 3], hi: [usize; 3]) -> Vec<(usize, usize)> {
        let [nx, ny, _] = self.dims;
        let mut runs: Vec<(usize, usize)> = Vec::new();
        for z in lo[2]..hi[2] {
            for y in lo[1]..hi[1] {
                let start = lo[0] + nx * (y + ny * z);
                let len = hi[0] - lo[0];
                match runs.last_mut() {
                    Some((s, l)) if *s + *l == start => *l += len,
                    _ => runs.push((start, len)),
                }
            }
        }
        runs
    }

    /// Box `lo..hi` into `out` (resized to its cells x k values, box-local x fastest).
    pub fn read_box(&self, lo: [usize; 3], hi: [usize; 3], out: &mut Vec<Vec3>) -> Result<()> {
        let cells: usize = (0..3).map(|a| hi[a] - lo[a]).product();
        out.clear();
        out.reserve_exact(cells * self.k);
        let mut bytes = Vec::new();
        for (start, len) in self.runs(lo, hi) {
            bytes.resize(len * self.k * VALUE_BYTES, 0);
            read_exact_at(&self.file, &mut bytes, (start * self.k * VALUE_BYTES) as u64).map_err(|e| self.error(e))?;
            out.extend(bytes.chunks_exact(VALUE_BYTES).map(|b| {
                let f = |i: usize| f32::from_le_bytes([b[i], b[i + 1], b[i + 2], b[i + 3]]);
                Vec3::new(f(0), f(4), f(8))
            }));
        }
        Ok(())
    }

    /// `data` (as `read_box` gives it) into box `lo..hi`.
    pub fn write_box(&self, lo: [usize; 3], hi: [usize; 3], data: &[Vec3]) -> Result<()> {
        let mut bytes = Vec::new();
        let mut at = 0;
        for (start, len) in self.runs(lo, hi) {
            bytes.clear();
            for v in &data[at..at + len * self.k] {
                for c in v.to_array() {
                    bytes.extend_from_slice(&c.to_le_bytes());
                }
            }
            at += len * self.k;
            write_all_at(&self.file, &bytes, (start * self.k * VALUE_BYTES) as u64).map_err(|e| self.error(e))?;
        }
        Ok(())
    }
}

impl Drop for SlabStore {
    fn drop(&mut self) {
        // Nothing to report to: a scratch file that cannot be removed is left for the OS's
        // temp cleaning.
        #[cfg(not(unix))]
        let _ = std::fs::remove_file(&self.path);
    }
}

#[cfg(unix)]
fn read_exact_at(f: &File, buf: &mut [u8], at: u64) -> std::io::Result<()> {
    std::os::unix::fs::FileExt::read_exact_at(f, buf, at)
}

#[cfg(unix)]
fn write_all_at(f: &File, buf: &[u8], at: u64) -> std::io::Result<()> {
    std::os::unix::fs::FileExt::write_all_at(f, buf, at)
}

#[cfg(windows)]
fn read_exact_at(f: &File, mut buf: &mut [u8], mut at: u64) -> std::io::Result<()> {
    while !buf.is_empty() {
        match std::os::windows::fs::FileExt::seek_read(f, buf, at)? {
            0 => return Err(std::io::ErrorKind::UnexpectedEof.into()),
            n => {
                buf = &mut buf[n..];
                at += n as u64;
            }
        }
    }
    Ok(())
}

#[cfg(windows)]
fn write_all_at(f: &File, mut buf: &[u8], mut at: u64) -> std::io::Result<()> {
    while !buf.is_empty() {
        match std::os::windows::fs::FileExt::seek_write(f, buf, at)? {
            0 => return Err(std::io::ErrorKind::WriteZero.into()),
            n => {
                buf = &buf[n..];
                at += n as u64;
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Boxes along each axis round-trip, a fresh store reads zero, and the file is gone after
    /// the store is dropped.
    #[test]
    fn slab_store_boxes_round_trip_and_the_file_is_removed() {
        let dir = std::env::temp_dir();
        let dims = [5, 4, 3];
        let s = SlabStore::create(&dir, "test", dims, 2).unwrap();
        let path = s.path().to_path_buf();
        let mut v = Vec::new();
        s.read_box([0; 3], dims, &mut v).unwrap();
        assert_eq!(v.len(), 5 * 4 * 3 * 2);
        assert!(v.iter().all(|x| *x == Vec3::ZERO));
        let value = |c: [usize; 3], k: usize| Vec3::new(c[0] as f32, c[1] as f32 * 10.0, c[2] as f32 * 100.0 + k as f32);
        // Write the whole array as x-slabs of 2, read it back as y-slabs and z-slabs.
        let boxes = |axis: usize, t: usize| (0..dims[axis]).step_by(t).map(move |a| {
            let (mut lo, mut hi) = ([0; 3], dims);
            lo[axis] = a;
            hi[axis] = (a + t).min(dims[axis]);
            (lo, hi)
        });
        let fill = |lo: [usize; 3], hi: [usize; 3]| {
            let mut d = Vec::new();
            for z in lo[2]..hi[2] {
                for y in lo[1]..hi[1] {
                    for x in lo[0]..hi[0] {
                        d.extend((0..2).map(|k| value([x, y, z], k)));
                    }
                }
            }
            d
        };
        for (lo, hi) in boxes(0, 2) {
            s.write_box(lo, hi, &fill(lo, hi)).unwrap();
        }
        for axis in [1, 2, 0] {
            for (lo, hi) in boxes(axis, 2) {
                s.read_box(lo, hi, &mut v).unwrap();
                assert_eq!(v, fill(lo, hi), "axis {axis} box {lo:?}..{hi:?}");
            }
        }
        // Unlinked once open (nothing survives a SIGKILL); elsewhere removed on drop.
        assert_eq!(path.exists(), !cfg!(unix));
        drop(s);
        assert!(!path.exists());
    }

    /// A directory that does not exist is a clear error naming the file, not a panic.
    #[test]
    fn slab_store_in_a_missing_directory_is_an_error() {
        let err = SlabStore::create(Path::new("/nonexistent/volscatter"), "u", [2, 2, 2], 1).err().unwrap().to_string();
        assert!(err.contains("volscatter-lpm") && err.contains("TMPDIR"), "the file and the hint: {err}");
    }
}
