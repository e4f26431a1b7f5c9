//! OpenVDB reader and writer (issue 2/9), written by hand for this project.
//!
//! Why not a crate: `vdb-rs` 0.6.0, the only Rust VDB reader on crates.io, fails on every
//! half-precision grid (Blender's fluid-cache default), overflows the heap on crafted Blosc
//! chunks, never checks the magic number, drops root tiles, misreads vec3 grids as float and
//! panics or aborts on valid files (`shared/notes/vdb-format.md` has the measurements). A panic
//! inside Blender kills Blender, so this module reads every size from the file as untrusted:
//! each count and offset is checked against the bytes left and against what the node implies
//! before anything is allocated, and compressed chunks decode into buffers of exactly the
//! size the node needs.
//!
//! Read: file versions 222..=225, float grids stored full or half, no compression / Zip /
//! Blosc, node metadata 0..=6 (mask compression), tiles at every level, every linear map
//! (`UniformScaleMap`, `ScaleMap`, `(Uniform)ScaleTranslateMap`, `TranslationMap`, `AffineMap`,
//! `UnitaryMap`), instanced grids. double / int32 / int64 / vec3s / vec3d / vec3i grids are
//! listed with statistics by [`inspect`] but refused as density; bool, mask and point grids
//! are listed by name and type only.
//!
//! Write: float grids, full or half, uncompressed or Zip, file version 224 ([`writer`]); a
//! dense RGB grid also z-planes at a time, for grids too large to hold ([`stream_writer`]); a
//! file mixing dense float and vec3s grids with grids copied byte for byte from another
//! version-224 file, written atomically ([`mixed_writer`], what hosts write through the C ABI).
//!
//! Modules: [`header`] (header, metadata, grid descriptors), [`transform`] (maps),
//! `tree` (5-4-3 topology and buffers), [`values`] (compressed value blocks), [`blosc`]
//! (Blosc and Zip chunks), `stats` (vdb-info numbers), [`writer`], [`mixed_writer`].

pub mod blosc;
mod bytes;
pub mod filter;
pub mod header;
pub mod mixed_writer;
mod stats;
pub mod stream_writer;
pub mod transform;
mod tree;
pub mod values;
pub mod writer;

#[cfg(test)]
mod filter_tests;
#[cfg(test)]
mod mixed_writer_tests;
#[cfg(test)]
mod region_tests;
#[cfg(test)]
mod tests;

use std::path::{Path, PathBuf};

use glam::{Affine3A, IVec3};
use serde::Serialize;

use crate::error::{excerpt, Error, Result};
use crate::medium::{DensityGrid, DensityGridBuilder, GridLimits};
use bytes::Reader;
use header::{FileHeader, GridDescriptor, MetaMap, MetaValue};
use transform::GridTransform;
use values::{Codec, ValueKind};

pub use filter::{load_density_filtered, FilterReport, MaxResolution};
pub use mixed_writer::{write_grids, DenseVec3s, GridCopy, GridSource};
pub use stream_writer::{FloatVdbStream, RgbVdbStream};
pub use writer::{write_dense_float_grids, write_float_grid, write_rgb_grids, DenseFloat, VdbCompression, WriteOptions};

/// An OpenVDB file with its header and grid descriptors parsed. Opened from disk, its bytes
/// stay there: each read goes through a window of `bytes::WINDOW` bytes (bytes.rs), so a file
/// larger than memory can be opened, inspected and read region by region or filtered
/// (filter.rs); `from_bytes` parses a file already in memory.
pub struct VdbFile {
    path: PathBuf,
    contents: Contents,
    pub header: FileHeader,
    pub metadata: MetaMap,
    pub grids: Vec<GridDescriptor>,
}

enum Contents {
    Mem(Vec<u8>),
    /// The open file and its size when opened.
    File(std::fs::File, usize),
}

/// The parts of a grid before its tree.
struct GridHead {
    compression: u32,
    metadata: MetaMap,
    transform: GridTransform,
    /// Offset where the tree (topology, then buffers) starts.
    tree_pos: usize,
}

impl VdbFile {
    /// Opens the file (its bytes are read as they are needed, not loaded); refuses files
    /// larger than `max_bytes`.
    pub fn open(path: &Path, max_bytes: u64) -> Result<Self> {
        // A FIFO passed as `medium.vdb` would block `read` forever (issue 22).
        let size = crate::io::files::regular_file(path, "VDB file")?;
        if size > max_bytes {
            return Err(Error::TooLarge(format!(
                "{}: file of {} MiB is over the limit of {} MiB",
                path.display(),
                size >> 20,
                max_bytes >> 20
            )));
        }
        let len = usize::try_from(size).map_err(|_| Error::TooLarge(format!("{}: file of {size} bytes", path.display())))?;
        let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
        Self::parse(Contents::File(file, len), path)
    }

    /// Parses a file already in memory; `path` names it in messages.
    pub fn from_bytes(data: Vec<u8>, path: &Path) -> Result<Self> {
        Self::parse(Contents::Mem(data), path)
    }

    fn parse(contents: Contents, path: &Path) -> Result<Self> {
        let (header, metadata, grids) = {
            let mut r = reader_of(&contents, None, path);
            let header = header::read_header(&mut r)?;
            if !header.has_grid_offsets {
                return Err(r.err("VDB streams without grid offsets are not supported; save the grids to a file"));
            }
            let metadata = header::read_meta_map(&mut r)?;
            let count = r.i32("grid count")?;
            // A descriptor takes at least 3 empty strings and 3 offsets.
            if count < 0 || count as u64 > r.remaining() as u64 / 36 {
                return Err(r.err(format!("grid count {count} does not fit in the file")));
            }
            let mut grids = Vec::with_capacity(count as usize);
            for _ in 0..count {
                let gd = header::read_descriptor(&mut r)?;
                if (gd.grid_pos as u64) < r.pos() as u64 {
                    return Err(r.err(format!("grid `{}` starts at {}, inside its own descriptor", excerpt(&gd.name), gd.grid_pos)));
                }
                r.seek(gd.end_pos, "grid end")?;
                grids.push(gd);
            }
            (header, metadata, grids)
        };
        Ok(VdbFile { path: path.to_path_buf(), contents, header, metadata, grids })
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// A reader limited to grid `i`'s bytes, positioned at its start.
    fn grid_reader(&self, i: usize) -> Result<Reader<'_>> {
        let gd = &self.grids[i];
        let mut r = reader_of(&self.contents, Some(gd.end_pos as usize), &self.path);
        r.seek(gd.grid_pos, "grid")?;
        Ok(r)
    }

    fn grid_head(&self, i: usize) -> Result<GridHead> {
        let mut r = self.grid_reader(i)?;
        let compression = r.u32("grid compression flags")?;
        if compression & !(header::COMPRESS_ZIP | header::COMPRESS_ACTIVE_MASK | header::COMPRESS_BLOSC) != 0 {
            return Err(r.err(format!("unknown compression flags {compression:#x}")));
        }
        let metadata = header::read_meta_map(&mut r)?;
        let transform = transform::read_transform(&mut r)?;
        Ok(GridHead { compression, metadata, transform, tree_pos: r.pos() })
    }

    /// `xf`, grid `i`'s index-to-world map (its file transform, maybe times the filter's
    /// coarse cells), when a medium can use it: finite and invertible in f32 (the file holds
    /// doubles, which may be past f32's range); else an error naming the file and grid.
    fn checked_transform(&self, i: usize, head: &GridHead, xf: Affine3A) -> Result<Affine3A> {
        let det = glam::Mat3::from(xf.matrix3).determinant();
        if !xf.is_finite() || !det.is_finite() || det == 0.0 {
            return Err(Error::format(
                &self.path,
                format!("grid `{}`: transform {} is out of single-precision range", excerpt(&self.grids[i].name), excerpt(&head.transform.map_type)),
            ));
        }
        Ok(xf)
    }

    /// Index of the grid whose tree grid `i` uses (itself, or its instance parent).
    fn tree_owner(&self, i: usize) -> Result<usize> {
        let gd = &self.grids[i];
        if gd.instance_parent.is_empty() {
            return Ok(i);
        }
        let p = self
            .grids
            .iter()
            .position(|g| g.unique_name == gd.instance_parent && g.instance_parent.is_empty())
            .ok_or_else(|| {
                Error::format(&self.path, format!("grid `{}` is an instance of `{}`, which is not in the file", excerpt(&gd.name), excerpt(&gd.instance_parent)))
            })?;
        if self.grids[p].grid_type != gd.grid_type || self.grids[p].half != gd.half {
            return Err(Error::format(&self.path, format!("instance grid `{}` and its parent differ in type", excerpt(&gd.name))));
        }
        Ok(p)
    }

    /// Reads grid `i`'s tree into a visitor.
    fn visit_tree(&self, i: usize, kind: ValueKind, visitor: &mut dyn tree::Visitor) -> Result<()> {
        self.visit_tree_region(i, kind, visitor, None).map(|_| ())
    }

    /// `visit_tree` passing on only what meets `region` (see `tree::read_tree_region`);
    /// returns the leaves skipped.
    fn visit_tree_region(&self, i: usize, kind: ValueKind, visitor: &mut dyn tree::Visitor, region: Option<(IVec3, IVec3)>) -> Result<usize> {
        self.visit_tree_windowed(i, kind, visitor, region).map(|(skipped, _)| skipped)
    }

    /// `visit_tree_region`, also returning the largest read window it held (0 in memory).
    fn visit_tree_windowed(&self, i: usize, kind: ValueKind, visitor: &mut dyn tree::Visitor, region: Option<(IVec3, IVec3)>) -> Result<(usize, usize)> {
        let owner = self.tree_owner(i)?;
        let head = self.grid_head(owner)?;
        let gd = &self.grids[owner];
        if gd.half && !kind.is_real() {
            return Err(Error::format(&self.path, format!("grid `{}`: half precision on a non-real value type", excerpt(&gd.name))));
        }
        let mut r = self.grid_reader(owner)?;
        r.seek(head.tree_pos as i64, "tree")?;
        let mut codec = Codec { kind, half: gd.half, compression: head.compression, background: vec![0.0; kind.comps] };
        let skipped = tree::read_tree_region(&mut r, &mut codec, visitor, region)?;
        Ok((skipped, r.peak_window()))
    }

    /// Index of the grid `name` (its name without uniqueness suffix, or its unique name), or
    /// with `None` the grid named "density", else the first float grid.
    pub fn find_density_grid(&self, name: Option<&str>) -> Result<usize> {
        let listing = || {
            let names = self.grids
                .iter()
                .map(|g| format!("`{}` ({}{})", excerpt(&g.name), excerpt(ValueKind::type_name(&g.grid_type)), if g.half { ", half" } else { "" }))
                .collect::<Vec<_>>()
                .join(", ");
            // A file may hold thousands of grids: the listing is quoted like any input.
            excerpt(&names).into_owned()
        };
        let is_float = |g: &GridDescriptor| ValueKind::from_tree_type(&g.grid_type) == Some(ValueKind::FLOAT);
        let i = match name {
            Some(n) => self.grids.iter().position(|g| g.name == n || g.unique_name == n).ok_or_else(|| {
                Error::format(&self.path, format!("no grid named `{}`; the file has {}", excerpt(n), listing()))
            })?,
            None => self
                .grids
                .iter()
                .position(|g| g.name == "density" && is_float(g))
                .or_else(|| self.grids.iter().position(is_float))
                .ok_or_else(|| Error::format(&self.path, format!("no float grid to use as density; the file has {}", listing())))?,
        };
        let g = &self.grids[i];
        if !is_float(g) {
            return Err(Error::format(
                &self.path,
                format!(
                    "grid `{}` holds {} values, not float: it cannot be used as density (grids: {})",
                    excerpt(&g.name),
                    excerpt(ValueKind::type_name(&g.grid_type)),
                    listing()
                ),
            ));
        }
        Ok(i)
    }

    /// Loads float grid `i` into a sparse density grid, with its index-to-world map.
    pub fn load_float_grid(&self, i: usize, limits: GridLimits) -> Result<(DensityGrid, Affine3A)> {
        self.load_float_grid_region(i, limits, None).map(|(g, xf, _)| (g, xf))
    }

    /// `load_float_grid` of only the leaves and tiles that meet the index box `region`
    /// (`lo..hi`, e.g. a slab of z): the other leaves are stepped over without decoding
    /// (compressed ones by their size prefix). Also returns how many leaves were skipped.
    pub fn load_float_grid_region(&self, i: usize, limits: GridLimits, region: Option<(IVec3, IVec3)>) -> Result<(DensityGrid, Affine3A, usize)> {
        let head = self.grid_head(i)?;
        let mut v = DensityVisitor { builder: DensityGridBuilder::new(limits), path: self.path.clone() };
        let name = self.grids[i].name.clone();
        let res = self.visit_tree_region(i, ValueKind::FLOAT, &mut v, region);
        let skipped = match res {
            Ok(n) => n,
            Err(Error::InvalidArgument(m)) => return Err(Error::format(&self.path, format!("grid `{}`: {m}", excerpt(&name)))),
            Err(e) => return Err(e),
        };
        let xf = self.checked_transform(i, &head, head.transform.to_affine3a())?;
        let grid = v.builder.build()?;
        Ok((grid, xf, skipped))
    }

    /// Everything `vdb-info` prints about grid `i`.
    pub fn grid_info(&self, i: usize) -> Result<GridInfo> {
        let gd = &self.grids[i];
        let head = self.grid_head(i)?;
        let kind = ValueKind::from_tree_type(&gd.grid_type);
        let class = match header::meta_get(&head.metadata, "class") {
            Some(MetaValue::String(s)) => s.clone(),
            _ => "unknown".to_string(),
        };
        let mut info = GridInfo {
            name: gd.name.clone(),
            unique_name: gd.unique_name.clone(),
            value_type: ValueKind::type_name(&gd.grid_type).to_string(),
            tree_type: gd.grid_type.clone(),
            half: gd.half,
            class,
            compression: compression_name(head.compression),
            transform: head.transform.map_type.clone(),
            index_to_world: row_major(&head.transform),
            instance_parent: (!gd.instance_parent.is_empty()).then(|| gd.instance_parent.clone()),
            bbox_min: None,
            bbox_max: None,
            active_voxels: None,
            sum: None,
            note: None,
            metadata: head
                .metadata
                .iter()
                .filter(|(_, v)| !matches!(v, MetaValue::Other { .. }))
                .map(|(k, v)| (k.clone(), v.clone()))
                .collect(),
        };
        match kind {
            Some(kind) => {
                let mut s = stats::Stats::new(kind.comps);
                self.visit_tree(i, kind, &mut s)?;
                if !s.is_empty() {
                    info.bbox_min = Some(s.bbox_min);
                    info.bbox_max = Some(s.bbox_max);
                }
                info.active_voxels = Some(s.active_voxels);
                info.sum = Some(if kind.comps == 1 { Sum::Scalar(s.sum[0]) } else { Sum::Vector(s.sum) });
            }
            None => {
                info.note = Some(format!("values of type `{}` are listed, not read", excerpt(&info.value_type)));
            }
        }
        Ok(info)
    }
}

/// A reader of the first `end` bytes (all of them with None); `end` was checked against the
/// size when the descriptors were read.
fn reader_of<'a>(contents: &'a Contents, end: Option<usize>, path: &'a Path) -> Reader<'a> {
    match contents {
        Contents::Mem(d) => Reader::new(&d[..end.unwrap_or(d.len())], path),
        Contents::File(f, len) => Reader::file(f, end.unwrap_or(*len), path),
    }
}

fn compression_name(c: u32) -> String {
    let mut parts = Vec::new();
    if c & header::COMPRESS_BLOSC != 0 {
        parts.push("blosc");
    } else if c & header::COMPRESS_ZIP != 0 {
        parts.push("zip");
    } else {
        parts.push("none");
    }
    if c & header::COMPRESS_ACTIVE_MASK != 0 {
        parts.push("active mask");
    }
    parts.join(" + ")
}

fn row_major(t: &GridTransform) -> [[f64; 4]; 4] {
    let m = glam::DMat4::from(t.index_to_world);
    [m.row(0).to_array(), m.row(1).to_array(), m.row(2).to_array(), m.row(3).to_array()]
}

#[derive(Clone, Debug, Serialize)]
#[serde(untagged)]
pub enum Sum {
    Scalar(f64),
    Vector(Vec<f64>),
}

/// One grid as `vdb-info` prints it.
#[derive(Clone, Debug, Serialize)]
pub struct GridInfo {
    pub name: String,
    pub unique_name: String,
    /// `float`, `vec3s`, `double`, `int32`, `bool`, ...
    pub value_type: String,
    pub tree_type: String,
    pub half: bool,
    pub class: String,
    pub compression: String,
    pub transform: String,
    /// Row-major 4x4, column vectors (`world = M * [i j k 1]`), like `medium.transform`.
    pub index_to_world: [[f64; 4]; 4],
    #[serde(skip_serializing_if = "Option::is_none")]
    pub instance_parent: Option<String>,
    /// Inclusive index bounding box of the active voxels and tiles (None when empty or unread).
    pub bbox_min: Option<[i64; 3]>,
    pub bbox_max: Option<[i64; 3]>,
    /// Active voxels, tiles counted by the voxels they cover. None for unread value types.
    pub active_voxels: Option<u64>,
    /// Sum of the active values (per component for vectors).
    pub sum: Option<Sum>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub note: Option<String>,
    /// Grid metadata of known types, by name.
    pub metadata: std::collections::BTreeMap<String, MetaValue>,
}

/// `vdb-info` for a whole file.
#[derive(Clone, Debug, Serialize)]
pub struct FileInfo {
    pub file: String,
    pub file_version: u32,
    pub library_version: String,
    pub grids: Vec<GridInfo>,
}

/// Reads every grid's statistics (no densifying: a 4096^3 root tile costs nothing).
pub fn inspect(path: &Path) -> Result<FileInfo> {
    let f = VdbFile::open(path, GridLimits::default().max_bytes)?;
    let mut grids = Vec::with_capacity(f.grids.len());
    for i in 0..f.grids.len() {
        grids.push(f.grid_info(i)?);
    }
    Ok(FileInfo {
        file: path.display().to_string(),
        file_version: f.header.version,
        library_version: format!("{}.{}", f.header.library_major, f.header.library_minor),
        grids,
    })
}

/// Loads a float grid (by name, or "density", else the first float grid) into a density
/// grid, with its index-to-object map.
pub fn load_density(path: &Path, grid: Option<&str>, limits: GridLimits) -> Result<(DensityGrid, Affine3A)> {
    let f = VdbFile::open(path, limits.max_bytes)?;
    let i = f.find_density_grid(grid)?;
    f.load_float_grid(i, limits)
}

/// A density grid's background must be 0 (what the sampling assumes outside the stored voxels).
fn density_background(path: &Path, value: &[f64]) -> Result<()> {
    if value[0] != 0.0 {
        return Err(Error::format(
            path,
            format!(
                "background value is {}: a density grid needs background 0 (a level set is not a density; \
                 convert it to a fog volume first)",
                value[0]
            ),
        ));
    }
    Ok(())
}

/// Fills a density grid builder from a float tree.
struct DensityVisitor {
    builder: DensityGridBuilder,
    path: PathBuf,
}

impl tree::Visitor for DensityVisitor {
    fn background(&mut self, value: &[f64]) -> Result<()> {
        density_background(&self.path, value)
    }

    fn tile(&mut self, origin: IVec3, log2: u32, value: &[f64], _active: bool) -> Result<()> {
        // Inactive tiles with a non-background value are sampled by OpenVDB too.
        self.builder.fill_tile(origin, 1 << log2, value[0] as f32)
    }

    fn leaf(&mut self, origin: IVec3, _mask: &[u64; 8], values: &[f64]) -> Result<()> {
        let mut xf = [0.0f32; 512];
        for x in 0..8usize {
            for y in 0..8usize {
                for z in 0..8usize {
                    xf[x | (y << 3) | (z << 6)] = values[(x << 6) | (y << 3) | z] as f32;
                }
            }
        }
        self.builder.set_leaf(origin, &xf)
    }
}
