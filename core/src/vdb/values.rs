//! Value types of grids and the compressed value blocks of nodes
//! (`openvdb/io/Compression.h`, `readCompressedValues` / `writeCompressedValues`).

use super::blosc::{blosc_decompress_exact, to_error, zip_compress, zip_decompress_exact};
use super::bytes::{bit, count_on, Reader, Writer};
use super::header::{COMPRESS_ACTIVE_MASK, COMPRESS_BLOSC, COMPRESS_ZIP};
use crate::error::Result;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Scalar {
    F32,
    F64,
    I32,
    I64,
}

impl Scalar {
    fn size(self) -> usize {
        match self {
            Scalar::F32 | Scalar::I32 => 4,
            Scalar::F64 | Scalar::I64 => 8,
        }
    }
}

/// The value type of a `Tree_<type>_5_4_3` grid whose values this reader can decode.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ValueKind {
    pub scalar: Scalar,
    pub comps: usize,
}

impl ValueKind {
    pub const FLOAT: ValueKind = ValueKind { scalar: Scalar::F32, comps: 1 };

    /// Value type name from a tree type such as `Tree_vec3s_5_4_3` (half suffix removed).
    pub fn type_name(tree_type: &str) -> &str {
        tree_type.strip_prefix("Tree_").and_then(|s| s.strip_suffix("_5_4_3")).unwrap_or(tree_type)
    }

    /// None for trees this reader does not decode (bool, mask, points, other node sizes).
    pub fn from_tree_type(tree_type: &str) -> Option<ValueKind> {
        if !(tree_type.starts_with("Tree_") && tree_type.ends_with("_5_4_3")) {
            return None;
        }
        let (scalar, comps) = match Self::type_name(tree_type) {
            "float" => (Scalar::F32, 1),
            "double" => (Scalar::F64, 1),
            "int32" => (Scalar::I32, 1),
            "int64" => (Scalar::I64, 1),
            "vec3s" => (Scalar::F32, 3),
            "vec3d" => (Scalar::F64, 3),
            "vec3i" => (Scalar::I32, 3),
            _ => return None,
        };
        Some(ValueKind { scalar, comps })
    }

    /// Bytes of one value at full precision (background, tiles, inactive values).
    pub fn full_size(&self) -> usize {
        self.scalar.size() * self.comps
    }
    pub fn is_real(&self) -> bool {
        matches!(self.scalar, Scalar::F32 | Scalar::F64)
    }

    /// Decodes one full-size value into `out` (`comps` entries).
    pub fn decode_full(&self, b: &[u8], out: &mut [f64]) {
        let s = self.scalar.size();
        for (c, o) in out.iter_mut().enumerate().take(self.comps) {
            let x = &b[c * s..c * s + s];
            *o = match self.scalar {
                Scalar::F32 => f32::from_le_bytes([x[0], x[1], x[2], x[3]]) as f64,
                Scalar::I32 => i32::from_le_bytes([x[0], x[1], x[2], x[3]]) as f64,
                Scalar::F64 => f64::from_le_bytes([x[0], x[1], x[2], x[3], x[4], x[5], x[6], x[7]]),
                Scalar::I64 => i64::from_le_bytes([x[0], x[1], x[2], x[3], x[4], x[5], x[6], x[7]]) as f64,
            };
        }
    }
}

/// How the values of one grid are stored: value type, half flag, compression flags, and the
/// background (the inactive value that mask compression leaves out).
#[derive(Clone, Debug)]
pub(crate) struct Codec {
    pub kind: ValueKind,
    pub half: bool,
    pub compression: u32,
    pub background: Vec<f64>,
}

impl Codec {
    fn stored_size(&self) -> usize {
        if self.half {
            2 * self.kind.comps
        } else {
            self.kind.full_size()
        }
    }

    fn read_full(&self, r: &mut Reader, what: &str) -> Result<Vec<f64>> {
        let b = r.bytes(self.kind.full_size(), what)?;
        let mut v = vec![0.0; self.kind.comps];
        self.kind.decode_full(b, &mut v);
        Ok(v)
    }

    /// Reads one compressed values block of `count` values into `out`
    /// (`count * comps` entries), restoring the inactive values left out by mask compression.
    pub fn read_block(&self, r: &mut Reader, count: usize, mask: &[u64], out: &mut Vec<f64>) -> Result<()> {
        self.read_or_skip(r, count, mask, Some(out))
    }

    /// Moves the reader over one values block without decoding it (its sizes are checked as
    /// `read_block` checks them; a compressed chunk is stepped over by its size prefix).
    pub fn skip_block(&self, r: &mut Reader, count: usize, mask: &[u64]) -> Result<()> {
        self.read_or_skip(r, count, mask, None)
    }

    fn read_or_skip(&self, r: &mut Reader, count: usize, mask: &[u64], out: Option<&mut Vec<f64>>) -> Result<()> {
        let comps = self.kind.comps;
        let start = r.pos();
        let metadata = r.i8("node metadata")?;
        if !(0..=6).contains(&metadata) {
            return Err(to_error(r.path(), start, format!("node metadata {metadata} is not one of 0..6")));
        }
        let mut inactive1 = self.background.clone();
        let mut inactive0: Vec<f64> =
            if metadata == 0 { self.background.clone() } else { self.background.iter().map(|v| -v).collect() };
        if matches!(metadata, 2 | 4 | 5) {
            inactive0 = self.read_full(r, "inactive value")?;
            if metadata == 5 {
                inactive1 = self.read_full(r, "second inactive value")?;
            }
        }
        let selection = if matches!(metadata, 3..=5) { Some(r.mask(count / 64, "selection mask")?) } else { None };
        let stored = if self.compression & COMPRESS_ACTIVE_MASK != 0 && metadata != 6 { count_on(mask) } else { count };
        let nbytes = stored * self.stored_size();
        let mut raw_owned;
        let raw: &[u8] = if self.half && stored == 0 {
            &[]
        } else if self.compression & (COMPRESS_BLOSC | COMPRESS_ZIP) != 0 {
            let at = r.pos();
            let n = r.i64("compressed size")?;
            if n <= 0 {
                let m = n.unsigned_abs();
                if m != nbytes as u64 {
                    return Err(to_error(r.path(), at, format!("uncompressed chunk of {m} bytes where the node needs {nbytes}")));
                }
                if out.is_none() {
                    r.skip(nbytes, "uncompressed values")?;
                    &[]
                } else {
                    r.bytes(nbytes, "uncompressed values")?
                }
            } else if out.is_none() {
                r.skip(n as usize, "compressed values")?;
                &[]
            } else {
                if n as u64 > r.remaining() as u64 {
                    return Err(to_error(
                        r.path(),
                        at,
                        format!("compressed chunk of {n} bytes runs past the end of the grid ({} bytes left)", r.remaining()),
                    ));
                }
                let chunk = r.bytes(n as usize, "compressed values")?;
                raw_owned = vec![0u8; nbytes];
                let res = if self.compression & COMPRESS_BLOSC != 0 {
                    blosc_decompress_exact(chunk, &mut raw_owned)
                } else {
                    zip_decompress_exact(chunk, &mut raw_owned)
                };
                res.map_err(|m| to_error(r.path(), at, m))?;
                &raw_owned
            }
        } else if out.is_none() {
            r.skip(nbytes, "values")?;
            &[]
        } else {
            r.bytes(nbytes, "values")?
        };
        let Some(out) = out else { return Ok(()) };
        // Decode the stored values straight into `out` when nothing was left out, else into
        // a temporary that the mask then spreads.
        let decode = |dst: &mut Vec<f64>| {
            dst.clear();
            if self.half {
                dst.extend(raw.chunks_exact(2).map(|h| half::f16::from_le_bytes([h[0], h[1]]).to_f64()));
            } else if self.kind == ValueKind::FLOAT {
                dst.extend(raw.chunks_exact(4).map(|x| f32::from_le_bytes([x[0], x[1], x[2], x[3]]) as f64));
            } else {
                let s = self.kind.full_size();
                dst.resize(stored * comps, 0.0);
                for (i, v) in raw.chunks_exact(s).enumerate() {
                    self.kind.decode_full(v, &mut dst[i * comps..(i + 1) * comps]);
                }
            }
        };
        if stored == count {
            decode(out);
            return Ok(());
        }
        let mut vals = Vec::with_capacity(stored * comps);
        decode(&mut vals);
        out.clear();
        out.reserve(count * comps);
        let mut j = 0;
        for i in 0..count {
            if bit(mask, i) {
                out.extend_from_slice(&vals[j * comps..(j + 1) * comps]);
                j += 1;
            } else if selection.as_deref().is_some_and(|s| bit(s, i)) {
                out.extend_from_slice(&inactive1);
            } else {
                out.extend_from_slice(&inactive0);
            }
        }
        Ok(())
    }
}

/// Writes a block of float values: only the active ones (metadata 0) when every inactive
/// value is +0.0 (the background), else all of them (metadata 6). `compression` is the grid's
/// flags (ACTIVE_MASK always set by the writer, plus ZIP or nothing).
pub(crate) fn write_float_block(w: &mut Writer, values: &[f32], mask: &[u64], half: bool, compression: u32) {
    write_block(w, values, 1, mask, half, compression);
}

/// Writes a block of vec3s values (`values` holds 3 floats a value, `mask` a bit a value):
/// as [`write_float_block`], a value being inactive-background when all 3 floats are +0.0.
pub(crate) fn write_vec3s_block(w: &mut Writer, values: &[f32], mask: &[u64], half: bool, compression: u32) {
    write_block(w, values, 3, mask, half, compression);
}

/// The block of `values.len() / comps` values of `comps` floats each (float: 1, vec3s: 3).
fn write_block(w: &mut Writer, values: &[f32], comps: usize, mask: &[u64], half: bool, compression: u32) {
    let value = |i: usize| &values[i * comps..(i + 1) * comps];
    let count = values.len() / comps;
    let inactive_zero = (0..count).all(|i| bit(mask, i) || value(i).iter().all(|v| v.to_bits() == 0));
    let all: Vec<f32>;
    let data: &[f32] = if inactive_zero && compression & COMPRESS_ACTIVE_MASK != 0 {
        w.u8(0);
        all = (0..count).filter(|&i| bit(mask, i)).flat_map(value).copied().collect();
        &all
    } else {
        w.u8(6);
        values
    };
    if half && data.is_empty() {
        return;
    }
    let bytes: Vec<u8> = if half {
        // Clamped to the largest finite half: a value over 65504 would otherwise become inf.
        data.iter().flat_map(|v| half::f16::from_f32(v.clamp(-65504.0, 65504.0)).to_le_bytes()).collect()
    } else {
        data.iter().flat_map(|v| v.to_le_bytes()).collect()
    };
    if compression & COMPRESS_ZIP != 0 {
        let z = zip_compress(&bytes);
        if !z.is_empty() && z.len() < bytes.len() {
            w.i64(z.len() as i64);
            w.bytes(&z);
        } else {
            w.i64(-(bytes.len() as i64));
            w.bytes(&bytes);
        }
    } else {
        w.bytes(&bytes);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    fn codec(half: bool, compression: u32) -> Codec {
        Codec { kind: ValueKind::FLOAT, half, compression, background: vec![0.0] }
    }

    #[test]
    fn block_roundtrip_every_mode() {
        let mut mask = vec![0u64; 8];
        let mut values = vec![0.0f32; 512];
        for i in (0..512).step_by(7) {
            mask[i >> 6] |= 1 << (i & 63);
            values[i] = i as f32 * 0.5;
        }
        for half in [false, true] {
            for comp in [COMPRESS_ACTIVE_MASK, COMPRESS_ACTIVE_MASK | COMPRESS_ZIP, 0, COMPRESS_ZIP] {
                let mut w = Writer::default();
                write_float_block(&mut w, &values, &mask, half, comp);
                let mut r = Reader::new(&w.buf, Path::new("b"));
                let mut out = Vec::new();
                codec(half, comp).read_block(&mut r, 512, &mask, &mut out).unwrap();
                assert_eq!(r.remaining(), 0);
                for (a, b) in out.iter().zip(&values) {
                    let want = if half { half::f16::from_f32(*b).to_f32() } else { *b };
                    assert_eq!(*a as f32, want);
                }
            }
        }
        // Inactive non-zero values force metadata 6 and survive.
        values[1] = 3.0;
        let mut w = Writer::default();
        write_float_block(&mut w, &values, &mask, false, COMPRESS_ACTIVE_MASK);
        assert_eq!(w.buf[0], 6);
        let mut out = Vec::new();
        codec(false, COMPRESS_ACTIVE_MASK).read_block(&mut Reader::new(&w.buf, Path::new("b")), 512, &mask, &mut out).unwrap();
        assert_eq!(out[1], 3.0);
    }

    #[test]
    fn inactive_values_are_restored_per_metadata() {
        // 512 values, voxels 0..8 active; background 2.0 (as in a level set).
        let mut mask = vec![0u64; 8];
        mask[0] = 0xff;
        let mut sel = vec![0u64; 8];
        sel[1] = 1; // voxel 64 picks the second inactive value
        let c = Codec { kind: ValueKind::FLOAT, half: false, compression: COMPRESS_ACTIVE_MASK, background: vec![2.0] };
        // (metadata, inactive values written, selection mask written, expect at 9, expect at 64)
        let cases: [(u8, &[f32], bool, f64, f64); 6] = [
            (0, &[], false, 2.0, 2.0),
            (1, &[], false, -2.0, -2.0),
            (2, &[7.0], false, 7.0, 7.0),
            (3, &[], true, -2.0, 2.0),
            (4, &[7.0], true, 7.0, 2.0),
            (5, &[7.0, 9.0], true, 7.0, 9.0),
        ];
        for (meta, inactive, with_sel, at9, at64) in cases {
            let mut w = Writer::default();
            w.u8(meta);
            for v in inactive {
                w.f32(*v);
            }
            if with_sel {
                w.mask(&sel);
            }
            for i in 0..8 {
                w.f32(i as f32 + 0.5);
            }
            let mut out = Vec::new();
            c.read_block(&mut Reader::new(&w.buf, Path::new("b")), 512, &mask, &mut out).unwrap();
            assert_eq!(out.len(), 512);
            assert_eq!(out[3], 3.5, "metadata {meta}");
            assert_eq!((out[9], out[64]), (at9, at64), "metadata {meta}");
        }
    }

    #[test]
    fn lying_sizes_are_errors() {
        let mask = vec![u64::MAX; 8];
        for n in [i64::MIN, -1, 1 << 40, i64::MAX, 3] {
            let mut w = Writer::default();
            w.u8(6);
            w.i64(n);
            w.bytes(&[0u8; 64]);
            let mut out = Vec::new();
            let r = codec(false, COMPRESS_ZIP).read_block(&mut Reader::new(&w.buf, Path::new("b")), 512, &mask, &mut out);
            assert!(r.is_err(), "{n}");
            let r = codec(false, COMPRESS_BLOSC).read_block(&mut Reader::new(&w.buf, Path::new("b")), 512, &mask, &mut out);
            assert!(r.is_err(), "{n}");
        }
        let mut out = Vec::new();
        let r = codec(false, 0).read_block(&mut Reader::new(&[9u8], Path::new("b")), 512, &mask, &mut out);
        assert!(r.unwrap_err().to_string().contains("metadata"));
    }
}
