//! Bounds-checked little-endian reading of a file, held in memory or read from disk through
//! a bounded window. Every read checks the bytes left first; an error names the file, the
//! offset and what was being read.
//!
//! From disk (`Reader::file`), the reader keeps one window of the file (`WINDOW` bytes, more
//! only for a single read that is longer, up to `MAX_READ`) and fills it with positioned
//! reads, so a file larger than memory is parsed with a buffer of that size; `skip` moves over
//! bytes without reading them.

use std::fs::File;
use std::path::Path;

use crate::error::{Error, Result};

/// Bytes a file-backed reader reads at a time (a leaf of 512 floats is 2 KiB; the tree is read
/// mostly in order, so one window serves many nodes).
pub(crate) const WINDOW: usize = 64 << 10;

/// The longest single read from a file-backed reader. The largest block a valid file holds is
/// an internal node's values (32^3 vec3d, 768 KiB, a little more compressed) or a metadata
/// value; a size field claiming more is refused rather than allocated.
pub(crate) const MAX_READ: usize = 64 << 20;

enum Source<'a> {
    Mem(&'a [u8]),
    /// `buf` holds the file's bytes `at .. at + buf.len()`.
    File { file: &'a File, buf: Vec<u8>, at: usize },
}

pub(crate) struct Reader<'a> {
    src: Source<'a>,
    /// Bytes readable: the slice's length, or the end offset given for a file.
    len: usize,
    pos: usize,
    path: &'a Path,
    /// Largest window a file-backed reader has held (for tests and reports).
    peak_window: usize,
}

impl<'a> Reader<'a> {
    pub fn new(data: &'a [u8], path: &'a Path) -> Self {
        Reader { src: Source::Mem(data), len: data.len(), pos: 0, path, peak_window: 0 }
    }

    /// A reader of the file's first `len` bytes, read through a window (see the module docs).
    pub fn file(file: &'a File, len: usize, path: &'a Path) -> Self {
        Reader { src: Source::File { file, buf: Vec::new(), at: 0 }, len, pos: 0, path, peak_window: 0 }
    }

    pub fn path(&self) -> &'a Path {
        self.path
    }
    pub fn pos(&self) -> usize {
        self.pos
    }
    pub fn len(&self) -> usize {
        self.len
    }
    pub fn remaining(&self) -> usize {
        self.len - self.pos
    }
    /// A second reader of the same bytes at `pos` with its own window (the tree reader walks
    /// the topology again beside the leaf buffers, tree.rs).
    pub fn fork(&self, pos: usize) -> Reader<'a> {
        let src = match &self.src {
            Source::Mem(d) => Source::Mem(d),
            Source::File { file, .. } => Source::File { file, buf: Vec::new(), at: 0 },
        };
        Reader { src, len: self.len, pos, path: self.path, peak_window: 0 }
    }

    /// Bytes of the largest window held so far (0 for a reader of memory).
    pub fn peak_window(&self) -> usize {
        self.peak_window
    }

    /// A format error at the current offset. Names from the file are quoted as excerpts where
    /// messages are made; this cut (at 4 quote lengths) is the backstop for one that is not.
    pub fn err(&self, msg: impl std::fmt::Display) -> Error {
        let msg = msg.to_string();
        let msg = match msg.char_indices().nth(4 * crate::error::MAX_QUOTE_CHARS) {
            Some((end, _)) => format!("{}... ({} more bytes)", &msg[..end], msg.len() - end),
            None => msg,
        };
        Error::format(self.path, format!("at byte {}: {msg}", self.pos))
    }

    /// Moves to an absolute offset taken from the file (checked against the file size).
    pub fn seek(&mut self, pos: i64, what: &str) -> Result<()> {
        if pos < 0 || pos as u64 > self.len as u64 {
            return Err(self.err(format!("{what} offset {pos} lies outside the file ({} bytes)", self.len)));
        }
        self.pos = pos as usize;
        Ok(())
    }

    pub fn bytes(&mut self, n: usize, what: &str) -> Result<&[u8]> {
        if n > self.remaining() {
            return Err(self.err(format!(
                "truncated: {what} needs {n} bytes, {} left",
                self.remaining()
            )));
        }
        let start = self.pos;
        if let Source::File { buf, at, .. } = &self.src {
            let inside = start >= *at && start + n <= *at + buf.len();
            if !inside && n > MAX_READ {
                return Err(self.err(format!("{what} claims {n} bytes, more than any block of a valid file ({MAX_READ} bytes)")));
            }
        }
        self.pos += n;
        let path = self.path;
        match &mut self.src {
            Source::Mem(d) => Ok(&d[start..start + n]),
            Source::File { file, buf, at } => {
                if start < *at || start + n > *at + buf.len() {
                    let want = n.max(WINDOW).min(self.len - start);
                    buf.resize(want, 0);
                    *at = start;
                    self.peak_window = self.peak_window.max(buf.capacity());
                    if let Err(e) = read_exact_at(file, buf, start as u64) {
                        // The window is not valid: the next read refills it.
                        buf.clear();
                        return Err(Error::io(path, e));
                    }
                }
                Ok(&buf[start - *at..start - *at + n])
            }
        }
    }

    /// Moves over `n` bytes (checked against the bytes left; a file's are not read).
    pub fn skip(&mut self, n: usize, what: &str) -> Result<()> {
        if n > self.remaining() {
            return Err(self.err(format!(
                "truncated: {what} needs {n} bytes, {} left",
                self.remaining()
            )));
        }
        self.pos += n;
        Ok(())
    }

    pub fn array<const N: usize>(&mut self, what: &str) -> Result<[u8; N]> {
        let b = self.bytes(N, what)?;
        let mut a = [0u8; N];
        a.copy_from_slice(b);
        Ok(a)
    }

    pub fn u8(&mut self, what: &str) -> Result<u8> {
        Ok(self.array::<1>(what)?[0])
    }
    pub fn i8(&mut self, what: &str) -> Result<i8> {
        Ok(self.u8(what)? as i8)
    }
    pub fn u32(&mut self, what: &str) -> Result<u32> {
        Ok(u32::from_le_bytes(self.array(what)?))
    }
    pub fn i32(&mut self, what: &str) -> Result<i32> {
        Ok(i32::from_le_bytes(self.array(what)?))
    }
    pub fn i64(&mut self, what: &str) -> Result<i64> {
        Ok(i64::from_le_bytes(self.array(what)?))
    }
    pub fn f64(&mut self, what: &str) -> Result<f64> {
        Ok(f64::from_le_bytes(self.array(what)?))
    }

    /// OpenVDB string: uint32 length, then that many bytes (not NUL-terminated).
    pub fn string(&mut self, what: &str) -> Result<String> {
        let n = self.u32(what)? as usize;
        let b = self.bytes(n, what)?;
        Ok(String::from_utf8_lossy(b).into_owned())
    }

    /// A node mask of `words` uint64 words.
    pub fn mask(&mut self, words: usize, what: &str) -> Result<Vec<u64>> {
        let b = self.bytes(words * 8, what)?;
        Ok(b.chunks_exact(8).map(|c| u64::from_le_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]])).collect())
    }
}

/// A positioned read (no shared file offset, so readers of one file do not disturb each other).
#[cfg(unix)]
pub(crate) fn read_exact_at(f: &File, buf: &mut [u8], at: u64) -> std::io::Result<()> {
    std::os::unix::fs::FileExt::read_exact_at(f, buf, at)
}

#[cfg(not(unix))]
pub(crate) fn read_exact_at(mut f: &File, buf: &mut [u8], at: u64) -> std::io::Result<()> {
    use std::io::{Read, Seek, SeekFrom};
    f.seek(SeekFrom::Start(at))?;
    f.read_exact(buf)
}

/// Little-endian writing into a growing buffer, with offsets to patch afterwards.
#[derive(Default)]
pub(crate) struct Writer {
    pub buf: Vec<u8>,
}

impl Writer {
    pub fn pos(&self) -> usize {
        self.buf.len()
    }
    pub fn bytes(&mut self, b: &[u8]) {
        self.buf.extend_from_slice(b);
    }
    pub fn u8(&mut self, v: u8) {
        self.buf.push(v);
    }
    pub fn u32(&mut self, v: u32) {
        self.bytes(&v.to_le_bytes());
    }
    pub fn i32(&mut self, v: i32) {
        self.bytes(&v.to_le_bytes());
    }
    pub fn i64(&mut self, v: i64) {
        self.bytes(&v.to_le_bytes());
    }
    pub fn f32(&mut self, v: f32) {
        self.bytes(&v.to_le_bytes());
    }
    pub fn f64(&mut self, v: f64) {
        self.bytes(&v.to_le_bytes());
    }
    pub fn string(&mut self, s: &str) {
        self.u32(s.len() as u32);
        self.bytes(s.as_bytes());
    }
    pub fn mask(&mut self, words: &[u64]) {
        for w in words {
            self.bytes(&w.to_le_bytes());
        }
    }
    pub fn patch_i64(&mut self, at: usize, v: i64) {
        self.buf[at..at + 8].copy_from_slice(&v.to_le_bytes());
    }
}

/// Number of set bits in a mask.
pub(crate) fn count_on(mask: &[u64]) -> usize {
    mask.iter().map(|w| w.count_ones() as usize).sum()
}

#[inline]
pub(crate) fn bit(mask: &[u64], i: usize) -> bool {
    (mask[i >> 6] >> (i & 63)) & 1 != 0
}

/// Indices of the set bits, ascending.
pub(crate) fn ones(mask: &[u64]) -> impl Iterator<Item = usize> + '_ {
    mask.iter().enumerate().flat_map(|(wi, &w)| {
        let mut w = w;
        std::iter::from_fn(move || {
            if w == 0 {
                return None;
            }
            let b = w.trailing_zeros() as usize;
            w &= w - 1;
            Some(wi * 64 + b)
        })
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_check_bounds() {
        let data = [1u8, 0, 0, 0, 5];
        let mut r = Reader::new(&data, Path::new("x.vdb"));
        assert_eq!(r.u32("a").unwrap(), 1);
        assert!(r.u32("b").is_err());
        assert_eq!(r.u8("c").unwrap(), 5);
        let data = [0xff, 0xff, 0xff, 0xff];
        let mut r = Reader::new(&data, Path::new("x.vdb"));
        let e = r.string("name").unwrap_err().to_string();
        assert!(e.contains("truncated") && e.contains("name"), "{e}");
        assert!(r.seek(-1, "grid").is_err());
        assert!(r.seek(5, "grid").is_err());
    }

    #[test]
    fn mask_bits() {
        let m = [0b1010u64, 1 << 63];
        assert_eq!(count_on(&m), 3);
        assert_eq!(ones(&m).collect::<Vec<_>>(), vec![1, 3, 127]);
        assert!(bit(&m, 127) && !bit(&m, 0));
    }
}
