//! One OpenVDB file (version 224) of several kinds of grids sharing one index-to-world map, as
//! a host writes it (the USD bake: its `scatter` vec3s grid, float grids, and the medium's
//! density copied from the source file): dense float grids ([`DenseFloat`]), dense vec3s grids
//! ([`DenseVec3s`]) and grids copied byte for byte from another version-224 file
//! ([`GridCopy`]; a grid's bytes hold no absolute offsets, so they move unchanged). Float and
//! vec3s grids go through the writer's tree encoder (writer.rs); the file goes through
//! `io::files::write_file_atomic`, so `path` is either the old file or the whole new one.

use std::path::Path;

use glam::{Affine3A, DMat4, DVec4};

use super::bytes::read_exact_at;
use super::header;
use super::writer::{check_dense, file_head, unique_names, write_grid, GridMap, Tree, VdbCompression};
use super::{Contents, DenseFloat, VdbFile, WriteOptions};
use crate::error::{excerpt, Error, Result};

/// Largest source file a grid is copied from (only the grid's own bytes are read).
const MAX_COPY_SOURCE_BYTES: u64 = 1 << 40;

/// A dense vec3s array: 3 floats a voxel, voxels x fastest, voxel (0,0,0) at index (0,0,0).
/// A voxel is active when any of its floats is not 0.
pub struct DenseVec3s<'a> {
    pub name: &'a str,
    pub dims: [u32; 3],
    /// `3 * dims[0] * dims[1] * dims[2]` floats.
    pub values: &'a [f32],
}

/// Grid `grid` (its name or unique name) of the OpenVDB file `source`, copied byte for byte
/// under the name `name`. The source must be file version 224 (what this writer and OpenVDB
/// up to 12 write) and the grid not an instance; the copy keeps its own transform, values and
/// metadata (its `name` metadata too: OpenVDB shows that name, volscatter the descriptor's).
pub struct GridCopy<'a> {
    pub name: &'a str,
    pub source: &'a Path,
    pub grid: &'a str,
}

/// One grid of a file written by [`write_grids`].
pub enum GridSource<'a> {
    Float(DenseFloat<'a>),
    Vec3s(DenseVec3s<'a>),
    Copy(GridCopy<'a>),
}

impl GridSource<'_> {
    fn name(&self) -> &str {
        match self {
            GridSource::Float(g) => g.name,
            GridSource::Vec3s(g) => g.name,
            GridSource::Copy(c) => c.name,
        }
    }
}

/// How vec3s grids are written: full precision, uncompressed (active mask only), class
/// "unknown" (not a fog volume), their map in double precision as given.
fn vec3s_options() -> WriteOptions {
    WriteOptions { half: false, compression: VdbCompression::None, class: "unknown".into() }
}

/// Writes `grids`, in order, as one OpenVDB file at `path`, atomically (a temporary beside
/// `path`, renamed over it; on failure `path` is left as it was and no temporary remains).
/// Float and vec3s grids place voxel (i, j, k) at `index_to_world * (i, j, k, 1)` (an affine,
/// invertible map, finite in single precision): float grids are written with `options` and
/// the map in single precision, as every float grid of this writer; vec3s grids as
/// `vec3s_options` says. Copied grids keep their own map. Every source is checked, and every
/// copied grid read, before anything is written.
pub fn write_grids(path: &Path, grids: &[GridSource<'_>], index_to_world: DMat4, options: &WriteOptions) -> Result<()> {
    if grids.is_empty() {
        return Err(Error::InvalidArgument(format!("{}: no grids to write", path.display())));
    }
    let xf = single_precision_map(&index_to_world)?;
    let names = unique_names(grids.iter().map(|g| g.name()))?;
    for g in grids {
        match g {
            GridSource::Float(g) => {
                check_dense(g.dims, g.values.len(), g.name)?;
                check_finite(g.name, g.values)?;
            }
            GridSource::Vec3s(g) => {
                if g.values.len() % 3 != 0 {
                    return Err(Error::InvalidArgument(format!("{}: {} floats is not 3 a voxel", g.name, g.values.len())));
                }
                check_dense(g.dims, g.values.len() / 3, g.name)?;
                check_finite(g.name, g.values)?;
            }
            GridSource::Copy(_) => {}
        }
    }
    let mut copies = Vec::new();
    for g in grids {
        if let GridSource::Copy(c) = g {
            copies.push(read_copy(c)?);
        }
    }
    let mut w = file_head(path, grids.len(), xf, options)?;
    let mut copies = copies.into_iter();
    for (g, (unique, name)) in grids.iter().zip(names) {
        match g {
            GridSource::Float(g) => {
                let tree = Tree::from_dense(g.dims, |i| g.values[i]);
                write_grid(&mut w, &unique, name, &tree, GridMap::Single(xf), options);
            }
            GridSource::Vec3s(g) => {
                let v = g.values;
                let tree = Tree::from_dense(g.dims, |i| [v[3 * i], v[3 * i + 1], v[3 * i + 2]]);
                write_grid(&mut w, &unique, name, &tree, GridMap::Double(index_to_world), &vec3s_options());
            }
            GridSource::Copy(_) => {
                let c = copies.next().expect("one read copy per copied grid");
                w.string(&unique);
                w.string(&c.tree_type);
                w.string(""); // instance parent
                let start = (w.pos() + 24) as i64;
                w.i64(start);
                w.i64(start + c.block as i64);
                w.i64(start + c.body.len() as i64);
                w.bytes(&c.body);
            }
        }
    }
    super::writer::stamp_content_uuid(&mut w.buf);
    crate::io::files::write_file_atomic(path, &w.buf)
}

/// `m` (row 3 must be 0 0 0 1) in single precision, which must be finite and invertible.
fn single_precision_map(m: &DMat4) -> Result<Affine3A> {
    if !m.row(3).abs_diff_eq(DVec4::W, 1e-6) {
        return Err(Error::InvalidArgument(format!("index-to-world map: last row must be 0 0 0 1, got {:?}", m.row(3).to_array())));
    }
    let single = m.as_mat4();
    let det = single.determinant();
    if !single.is_finite() || !(det.is_finite() && det.abs() > 1e-12) {
        return Err(Error::InvalidArgument(format!("index-to-world map {m:?} is not finite and invertible in single precision")));
    }
    Ok(Affine3A::from_mat4(single))
}

fn check_finite(name: &str, values: &[f32]) -> Result<()> {
    match values.iter().position(|v| !v.is_finite()) {
        Some(i) => Err(Error::InvalidArgument(format!("{name}: value {i} is {}", values[i]))),
        None => Ok(()),
    }
}

/// A grid read for copying: its tree type as the descriptor names it, its bytes from the
/// grid's start to its end, and where its buffers start within them.
struct CopiedGrid {
    tree_type: String,
    body: Vec<u8>,
    block: u64,
}

fn read_copy(c: &GridCopy<'_>) -> Result<CopiedGrid> {
    let src = c.source;
    let f = VdbFile::open(src, MAX_COPY_SOURCE_BYTES)?;
    if f.header.version != header::WRITE_FILE_VERSION {
        return Err(Error::Unsupported {
            path: src.to_path_buf(),
            message: format!("file version {} (a grid is copied byte for byte from version {} files only)", f.header.version, header::WRITE_FILE_VERSION),
        });
    }
    let g = f
        .grids
        .iter()
        .find(|g| g.name == c.grid || g.unique_name == c.grid)
        .ok_or_else(|| Error::format(src, format!("no grid named `{}`", excerpt(c.grid))))?;
    if !g.instance_parent.is_empty() || g.block_pos == 0 {
        return Err(Error::Unsupported {
            path: src.to_path_buf(),
            message: format!("grid `{}` is an instance of `{}`; it cannot be copied", excerpt(&g.name), excerpt(&g.instance_parent)),
        });
    }
    // The offsets were checked against the file's size and each other when it was opened;
    // only the grid's own bytes are read.
    let (len, block) = match (u64::try_from(g.end_pos - g.grid_pos), u64::try_from(g.block_pos - g.grid_pos)) {
        (Ok(len), Ok(block)) if block <= len => (len, block),
        _ => return Err(Error::format(src, format!("grid `{}`: offsets out of order", excerpt(&g.name)))),
    };
    crate::budget::check(&format!("grid `{}` of {}", excerpt(&g.name), src.display()), len)?;
    let mut body = vec![0u8; len as usize];
    let at = g.grid_pos as u64;
    match &f.contents {
        Contents::File(file, _) => read_exact_at(file, &mut body, at).map_err(|e| Error::io(src, e))?,
        Contents::Mem(data) => body.copy_from_slice(&data[at as usize..(at + len) as usize]),
    }
    let tree_type = if g.half { format!("{}{}", g.grid_type, header::HALF_SUFFIX) } else { g.grid_type.clone() };
    Ok(CopiedGrid { tree_type, body, block })
}
