//! File header, metadata maps and grid descriptors.

use serde::Serialize;

use super::bytes::{Reader, Writer};
use crate::error::Result;

pub const MAGIC: u64 = 0x5644_4220;
/// Oldest file version read: node-mask compression (per-node metadata byte) appeared in 222.
pub const MIN_FILE_VERSION: u32 = 222;
/// Newest known: 225 (OpenVDB 13). Newer ones are refused rather than guessed at.
pub const MAX_FILE_VERSION: u32 = 225;
/// What the writer emits (OpenVDB 10-12); every OpenVDB since 10 reads it without warnings.
pub const WRITE_FILE_VERSION: u32 = 224;

pub const COMPRESS_ZIP: u32 = 0x1;
pub const COMPRESS_ACTIVE_MASK: u32 = 0x2;
pub const COMPRESS_BLOSC: u32 = 0x4;

#[derive(Clone, Debug)]
pub struct FileHeader {
    pub version: u32,
    pub library_major: u32,
    pub library_minor: u32,
    pub has_grid_offsets: bool,
    pub uuid: String,
}

pub(crate) fn read_header(r: &mut Reader) -> Result<FileHeader> {
    let magic = r.array::<8>("magic number")?;
    if u64::from_le_bytes(magic) != MAGIC {
        return Err(r.err("not an OpenVDB file (wrong magic number)"));
    }
    let version = r.u32("file version")?;
    if version < MIN_FILE_VERSION {
        return Err(r.err(format!(
            "OpenVDB file version {version} is too old (this reader needs {MIN_FILE_VERSION} or newer, \
             written by OpenVDB 3.0 and later); re-save the file with a current OpenVDB"
        )));
    }
    if version > MAX_FILE_VERSION {
        return Err(r.err(format!(
            "OpenVDB file version {version} is newer than this reader knows ({MAX_FILE_VERSION})"
        )));
    }
    let library_major = r.u32("library major version")?;
    let library_minor = r.u32("library minor version")?;
    let has_grid_offsets = r.u8("grid offsets flag")? != 0;
    let uuid = String::from_utf8_lossy(r.bytes(36, "UUID")?).into_owned();
    Ok(FileHeader { version, library_major, library_minor, has_grid_offsets, uuid })
}

/// A metadata value. Unknown types keep their type name and size.
#[derive(Clone, Debug, PartialEq, Serialize)]
#[serde(untagged)]
pub enum MetaValue {
    Bool(bool),
    Int(i64),
    Float(f64),
    String(String),
    Vec3i([i32; 3]),
    Vec3d([f64; 3]),
    Other { type_name: String, bytes: usize },
}

pub type MetaMap = Vec<(String, MetaValue)>;

pub(crate) fn meta_get<'m>(m: &'m MetaMap, name: &str) -> Option<&'m MetaValue> {
    m.iter().find(|(k, _)| k == name).map(|(_, v)| v)
}

pub(crate) fn read_meta_map(r: &mut Reader) -> Result<MetaMap> {
    let count = r.u32("metadata count")? as usize;
    // Each entry takes at least 12 bytes (two empty strings and a size).
    if count > r.remaining() / 12 {
        return Err(r.err(format!("metadata count {count} is more than the file can hold")));
    }
    let mut out = Vec::with_capacity(count);
    for _ in 0..count {
        let name = r.string("metadata name")?;
        let type_name = r.string("metadata type")?;
        let size = r.u32("metadata size")? as usize;
        let start = r.pos();
        // Owned: a file-backed reader's window moves on with the next read.
        let body = r.bytes(size, "metadata value")?.to_vec();
        let mut b = Reader::new(&body, r.path());
        let expect = |n: usize| -> Result<()> {
            if size != n {
                return Err(r_err(r, start, &name, &type_name, size, n));
            }
            Ok(())
        };
        let v = match type_name.as_str() {
            "bool" => {
                expect(1)?;
                MetaValue::Bool(b.u8("bool")? != 0)
            }
            "int32" => {
                expect(4)?;
                MetaValue::Int(b.i32("int32")? as i64)
            }
            "int64" => {
                expect(8)?;
                MetaValue::Int(b.i64("int64")?)
            }
            "float" => {
                expect(4)?;
                MetaValue::Float(f32::from_le_bytes(b.array("float")?) as f64)
            }
            "double" => {
                expect(8)?;
                MetaValue::Float(b.f64("double")?)
            }
            "string" => MetaValue::String(String::from_utf8_lossy(&body).into_owned()),
            "vec3i" => {
                expect(12)?;
                MetaValue::Vec3i([b.i32("x")?, b.i32("y")?, b.i32("z")?])
            }
            "vec3s" => {
                expect(12)?;
                let mut v = [0.0; 3];
                for c in &mut v {
                    *c = f32::from_le_bytes(b.array("vec3s")?) as f64;
                }
                MetaValue::Vec3d(v)
            }
            "vec3d" => {
                expect(24)?;
                MetaValue::Vec3d([b.f64("x")?, b.f64("y")?, b.f64("z")?])
            }
            _ => MetaValue::Other { type_name: type_name.clone(), bytes: size },
        };
        out.push((name, v));
    }
    Ok(out)
}

fn r_err(r: &Reader, start: usize, name: &str, ty: &str, size: usize, n: usize) -> crate::error::Error {
    crate::error::Error::format(
        r.path(),
        format!(
            "at byte {start}: metadata `{}` of type {} has size {size}, expected {n}",
            crate::error::excerpt(name),
            crate::error::excerpt(ty)
        ),
    )
}

pub(crate) fn write_meta_map(w: &mut Writer, m: &MetaMap) {
    // Unknown types are never built by the writer; skip them rather than write garbage.
    let known: Vec<_> = m.iter().filter(|(_, v)| !matches!(v, MetaValue::Other { .. })).collect();
    w.u32(known.len() as u32);
    for (name, v) in known {
        w.string(name);
        match v {
            MetaValue::Bool(b) => {
                w.string("bool");
                w.u32(1);
                w.u8(*b as u8);
            }
            MetaValue::Int(i) => {
                w.string("int64");
                w.u32(8);
                w.i64(*i);
            }
            MetaValue::Float(f) => {
                w.string("double");
                w.u32(8);
                w.f64(*f);
            }
            MetaValue::String(s) => {
                w.string("string");
                w.string(s);
            }
            MetaValue::Vec3i(v) => {
                w.string("vec3i");
                w.u32(12);
                for c in v {
                    w.i32(*c);
                }
            }
            MetaValue::Vec3d(v) => {
                w.string("vec3d");
                w.u32(24);
                for c in v {
                    w.f64(*c);
                }
            }
            MetaValue::Other { .. } => {}
        }
    }
}

/// What precedes each grid in a file.
#[derive(Clone, Debug)]
pub struct GridDescriptor {
    /// Name as stored, possibly with a "\x1e<n>" suffix making it unique.
    pub unique_name: String,
    /// Name without the uniqueness suffix.
    pub name: String,
    /// Tree type without the `_HalfFloat` suffix, e.g. `Tree_float_5_4_3`.
    pub grid_type: String,
    pub half: bool,
    pub instance_parent: String,
    pub grid_pos: i64,
    pub block_pos: i64,
    pub end_pos: i64,
}

pub(crate) const HALF_SUFFIX: &str = "_HalfFloat";
pub(crate) const NAME_SEP: char = '\u{1e}';

pub(crate) fn read_descriptor(r: &mut Reader) -> Result<GridDescriptor> {
    let unique_name = r.string("grid name")?;
    let mut grid_type = r.string("grid type")?;
    let half = grid_type.ends_with(HALF_SUFFIX);
    if half {
        grid_type.truncate(grid_type.len() - HALF_SUFFIX.len());
    }
    let instance_parent = r.string("instance parent name")?;
    let grid_pos = r.i64("grid offset")?;
    let block_pos = r.i64("block offset")?;
    let end_pos = r.i64("end offset")?;
    let len = r.len() as i64;
    // The block offset is 0 for instance grids (no buffers of their own); it is not needed
    // to read (OpenVDB reads the buffers right after the topology), only checked for range.
    let block_ok = block_pos == 0 || (grid_pos <= block_pos && block_pos <= end_pos);
    if !(0 <= grid_pos && grid_pos <= end_pos && end_pos <= len && block_ok) {
        return Err(r.err(format!(
            "grid `{}` has offsets grid {grid_pos}, blocks {block_pos}, end {end_pos} \
             that are out of order or past the end of the file ({len} bytes)",
            crate::error::excerpt(&unique_name)
        )));
    }
    let name = unique_name.split(NAME_SEP).next().unwrap_or("").to_string();
    Ok(GridDescriptor { unique_name, name, grid_type, half, instance_parent, grid_pos, block_pos, end_pos })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    #[test]
    fn meta_roundtrip_and_bad_sizes() {
        let m: MetaMap = vec![
            ("class".into(), MetaValue::String("fog volume".into())),
            ("half".into(), MetaValue::Bool(true)),
            ("count".into(), MetaValue::Int(-5)),
            ("bbox".into(), MetaValue::Vec3i([1, -2, 3])),
        ];
        let mut w = Writer::default();
        write_meta_map(&mut w, &m);
        let mut r = Reader::new(&w.buf, Path::new("m"));
        assert_eq!(read_meta_map(&mut r).unwrap(), m);

        // An int32 that claims 5 bytes.
        let mut w = Writer::default();
        w.u32(1);
        w.string("n");
        w.string("int32");
        w.u32(5);
        w.bytes(&[0; 5]);
        assert!(read_meta_map(&mut Reader::new(&w.buf, Path::new("m"))).is_err());
        // A count larger than the bytes.
        let mut w = Writer::default();
        w.u32(u32::MAX);
        assert!(read_meta_map(&mut Reader::new(&w.buf, Path::new("m"))).is_err());
    }

    #[test]
    fn header_refuses_bad_magic_and_versions() {
        let mut w = Writer::default();
        w.bytes(b"NOTAVDB!");
        w.u32(224);
        assert!(read_header(&mut Reader::new(&w.buf, Path::new("h"))).unwrap_err().to_string().contains("magic"));
        for (v, word) in [(220u32, "too old"), (300, "newer")] {
            let mut w = Writer::default();
            w.bytes(&MAGIC.to_le_bytes());
            w.u32(v);
            let e = read_header(&mut Reader::new(&w.buf, Path::new("h"))).unwrap_err().to_string();
            assert!(e.contains(word), "{e}");
        }
    }
}
