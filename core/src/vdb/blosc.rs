//! Blosc and Zip chunks of compressed value blocks, decoded into buffers of exactly the size
//! the node implies.
//!
//! Blosc: c-blosc 1.x (crate `blosc-src`, bundled source, BloscLZ and LZ4 codecs; OpenVDB writes
//! LZ4). The 16-byte chunk header is checked here first, following c-blosc's own fuzz harness:
//! format version, type size, uncompressed size equal to what the node needs, compressed size
//! equal to the chunk's length, block size within the buffer, then `blosc_cbuffer_validate`;
//! only then is `blosc_decompress_ctx` called, with a destination of exactly that size.

use crate::error::Error;

pub const BLOSC_HEADER: usize = 16;
const BLOSC_MEMCPYED: u8 = 0x2;

/// Fields of a c-blosc 1.x chunk header.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BloscHeader {
    pub version: u8,
    pub version_lz: u8,
    pub flags: u8,
    pub typesize: u8,
    pub nbytes: u32,
    pub blocksize: u32,
    pub cbytes: u32,
}

pub fn parse_blosc_header(chunk: &[u8]) -> Option<BloscHeader> {
    if chunk.len() < BLOSC_HEADER {
        return None;
    }
    let u = |i: usize| u32::from_le_bytes([chunk[i], chunk[i + 1], chunk[i + 2], chunk[i + 3]]);
    Some(BloscHeader {
        version: chunk[0],
        version_lz: chunk[1],
        flags: chunk[2],
        typesize: chunk[3],
        nbytes: u(4),
        blocksize: u(8),
        cbytes: u(12),
    })
}

/// Decompresses one Blosc chunk into `out`, whose length is the exact size expected.
/// Returns a message (without file context) on any disagreement.
pub fn blosc_decompress_exact(chunk: &[u8], out: &mut [u8]) -> std::result::Result<(), String> {
    let h = parse_blosc_header(chunk)
        .ok_or_else(|| format!("Blosc chunk of {} bytes is shorter than its 16-byte header", chunk.len()))?;
    if !(1..=2).contains(&h.version) {
        return Err(format!("Blosc chunk has format version {} (c-blosc 1.x writes 1 or 2)", h.version));
    }
    if h.typesize == 0 {
        return Err("Blosc chunk has type size 0".into());
    }
    if h.nbytes as usize != out.len() {
        return Err(format!("Blosc chunk holds {} bytes, the node needs {}", h.nbytes, out.len()));
    }
    if h.cbytes as usize != chunk.len() {
        return Err(format!("Blosc chunk header says {} compressed bytes, the file gives {}", h.cbytes, chunk.len()));
    }
    if out.is_empty() {
        return Ok(());
    }
    if h.blocksize == 0 || h.blocksize > h.nbytes {
        return Err(format!("Blosc chunk has block size {} for {} bytes", h.blocksize, h.nbytes));
    }
    if h.flags & BLOSC_MEMCPYED != 0 && h.cbytes as usize != h.nbytes as usize + BLOSC_HEADER {
        return Err(format!("stored Blosc chunk of {} bytes should be {} bytes", h.cbytes, h.nbytes as usize + BLOSC_HEADER));
    }
    let mut nbytes = 0usize;
    // SAFETY: `chunk` is a valid slice of `chunk.len()` bytes; c-blosc reads only within it.
    let ok = unsafe { blosc_src::blosc_cbuffer_validate(chunk.as_ptr().cast(), chunk.len(), &mut nbytes) };
    if ok != 0 || nbytes != out.len() {
        return Err("Blosc chunk header is not valid".into());
    }
    // SAFETY: the source is `chunk` (validated above, `cbytes == chunk.len()`), the destination
    // is `out` with its exact length as `destsize`; c-blosc writes at most `destsize` bytes.
    let n = unsafe {
        blosc_src::blosc_decompress_ctx(chunk.as_ptr().cast(), out.as_mut_ptr().cast(), out.len(), 1)
    };
    if n < 0 || n as usize != out.len() {
        return Err(format!("Blosc decompression failed (code {n}) for a chunk of {} bytes", out.len()));
    }
    Ok(())
}

/// Blosc-compresses `data` the way OpenVDB does (LZ4, byte shuffle, type size 4). Used by
/// tests to craft chunks; the writer itself emits Zip or no compression.
pub fn blosc_compress(data: &[u8]) -> Vec<u8> {
    let mut out = vec![0u8; data.len() + BLOSC_HEADER];
    let name = c"lz4";
    // SAFETY: `data` and `out` are valid for their lengths; destsize is `out.len()`.
    let n = unsafe {
        blosc_src::blosc_compress_ctx(
            9,
            1,
            4,
            data.len(),
            data.as_ptr().cast(),
            out.as_mut_ptr().cast(),
            out.len(),
            name.as_ptr(),
            0,
            1,
        )
    };
    out.truncate(n.max(0) as usize);
    out
}

/// Inflates a zlib stream into `out`, which must come out exactly full.
pub fn zip_decompress_exact(stream: &[u8], out: &mut [u8]) -> std::result::Result<(), String> {
    let mut d = flate2::Decompress::new(true);
    let status = d
        .decompress(stream, out, flate2::FlushDecompress::Finish)
        .map_err(|e| format!("Zip stream is corrupt: {e}"))?;
    let produced = d.total_out() as usize;
    match status {
        flate2::Status::StreamEnd if produced == out.len() => Ok(()),
        flate2::Status::StreamEnd => Err(format!("Zip stream holds {produced} bytes, the node needs {}", out.len())),
        _ if produced == out.len() => Err(format!("Zip stream holds more than the {} bytes the node needs", out.len())),
        _ => Err(format!("Zip stream ends early after {produced} of {} bytes", out.len())),
    }
}

pub fn zip_compress(data: &[u8]) -> Vec<u8> {
    use std::io::Write;
    let mut e = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
    // Writing into a Vec cannot fail.
    let _ = e.write_all(data);
    e.finish().unwrap_or_default()
}

pub(crate) fn to_error(path: &std::path::Path, at: usize, msg: String) -> Error {
    Error::format(path, format!("at byte {at}: {msg}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Vec<u8> {
        (0..2048u32).flat_map(|i| ((i % 37) as f32 * 0.25).to_le_bytes()).collect()
    }

    #[test]
    fn blosc_roundtrip_exact_size() {
        let data = sample();
        let c = blosc_compress(&data);
        assert!(c.len() >= BLOSC_HEADER && c.len() < data.len());
        let mut out = vec![0u8; data.len()];
        blosc_decompress_exact(&c, &mut out).unwrap();
        assert_eq!(out, data);
        // Wrong expected size either way.
        assert!(blosc_decompress_exact(&c, &mut vec![0u8; data.len() - 4]).is_err());
        assert!(blosc_decompress_exact(&c, &mut vec![0u8; data.len() + 4]).is_err());
        // Truncated chunk.
        assert!(blosc_decompress_exact(&c[..c.len() - 1], &mut out).is_err());
    }

    #[test]
    fn crafted_blosc_headers_are_refused() {
        let data = sample();
        let c = blosc_compress(&data);
        let mut out = vec![0u8; data.len()];
        let patch = |f: &dyn Fn(&mut Vec<u8>)| {
            let mut c2 = c.clone();
            f(&mut c2);
            c2
        };
        // A header claiming 500 MB, a lying cbytes, version 0 and 9, typesize 0, blocksize 0
        // and huge, memcpy flag with a compressed body.
        let cases = [
            patch(&|c| c[4..8].copy_from_slice(&500_000_000u32.to_le_bytes())),
            patch(&|c| {
                let n = (c.len() + 100) as u32;
                c[12..16].copy_from_slice(&n.to_le_bytes())
            }),
            patch(&|c| c[0] = 0),
            patch(&|c| c[0] = 9),
            patch(&|c| c[3] = 0),
            patch(&|c| c[8..12].copy_from_slice(&0u32.to_le_bytes())),
            patch(&|c| c[8..12].copy_from_slice(&u32::MAX.to_le_bytes())),
            patch(&|c| c[2] |= BLOSC_MEMCPYED),
        ];
        for (i, bad) in cases.iter().enumerate() {
            assert!(blosc_decompress_exact(bad, &mut out).is_err(), "case {i}");
        }
        // Corrupted body: must error or decode garbage, never write outside `out`.
        for i in BLOSC_HEADER..c.len() {
            let mut bad = c.clone();
            bad[i] ^= 0x5a;
            let mut out = vec![0u8; data.len()];
            let _ = blosc_decompress_exact(&bad, &mut out);
        }
    }

    #[test]
    fn zip_exact_size() {
        let data = sample();
        let z = zip_compress(&data);
        let mut out = vec![0u8; data.len()];
        zip_decompress_exact(&z, &mut out).unwrap();
        assert_eq!(out, data);
        assert!(zip_decompress_exact(&z, &mut vec![0u8; data.len() - 1]).is_err());
        assert!(zip_decompress_exact(&z, &mut vec![0u8; data.len() + 1]).is_err());
        assert!(zip_decompress_exact(&z[..z.len() / 2], &mut out).is_err());
        assert!(zip_decompress_exact(b"garbage!", &mut out).is_err());
    }
}
