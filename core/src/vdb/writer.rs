//! Writer of float and vec3s grids that OpenVDB reads back exactly: file version 224, full or
//! half precision, no compression or Zip, always with the active-mask flag (inactive values are
//! the background 0 and are left out; a node with other inactive values stores all of them).
//!
//! Sources: a [`DensityGrid`] (its constant bricks become active tiles of 8^3 voxels) or dense
//! x-fastest arrays with an index-to-world map, such as the RGB scattering grid, which goes out
//! as three float grids `<prefix>_r/_g/_b` (what Blender and USD read). One tree encoder
//! ([`Tree`]) serves both value types; a file mixing float, vec3s and copied grids is written
//! by [`super::mixed_writer::write_grids`].

use std::collections::BTreeMap;
use std::path::Path;

use glam::{Affine3A, DMat4, IVec3, Vec3};

use super::bytes::Writer;
use super::header::{self, MetaMap, MetaValue, COMPRESS_ACTIVE_MASK, COMPRESS_ZIP};
use super::transform::{write_affine_map, write_transform};
use super::values::{write_float_block, write_vec3s_block};
use crate::error::{Error, Result};
use crate::medium::grid::BrickRef;
use crate::medium::DensityGrid;

#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum VdbCompression {
    None,
    #[default]
    Zip,
}

#[derive(Clone, Debug)]
pub struct WriteOptions {
    /// Store values as 16-bit halves (`_HalfFloat` grids), as Blender's caches do.
    pub half: bool,
    pub compression: VdbCompression,
    /// Grid class metadata: "fog volume" (default) or "unknown".
    pub class: String,
}

impl Default for WriteOptions {
    fn default() -> Self {
        WriteOptions { half: false, compression: VdbCompression::Zip, class: "fog volume".into() }
    }
}

/// A dense float array, x fastest, voxel (0,0,0) at index (0,0,0).
pub struct DenseFloat<'a> {
    pub name: &'a str,
    pub dims: [u32; 3],
    pub values: &'a [f32],
}

type Key = (i32, i32, i32);

fn key(v: IVec3) -> Key {
    (v.x, v.y, v.z)
}

/// A value type the writer encodes: float (`f32`) or vec3s (`[f32; 3]`). Everything but the
/// value block and the tree type is shared.
pub(super) trait Voxel: Copy + PartialEq + 'static {
    /// The background (and the inactive value): 0.
    const ZERO: Self;
    /// The tree type, without the `_HalfFloat` suffix.
    const TREE_TYPE: &'static str;
    /// The grid's `vector_type` metadata (vector grids only).
    const VECTOR_TYPE: Option<&'static str>;
    /// The floats of `values`, in order.
    fn floats(values: &[Self]) -> &[f32];
    /// A compressed value block of `values` (values.rs).
    fn write_block(w: &mut Writer, values: &[Self], mask: &[u64], half: bool, compression: u32);
}

impl Voxel for f32 {
    const ZERO: Self = 0.0;
    const TREE_TYPE: &'static str = "Tree_float_5_4_3";
    const VECTOR_TYPE: Option<&'static str> = None;
    fn floats(values: &[Self]) -> &[f32] {
        values
    }
    fn write_block(w: &mut Writer, values: &[Self], mask: &[u64], half: bool, compression: u32) {
        write_float_block(w, values, mask, half, compression);
    }
}

impl Voxel for [f32; 3] {
    const ZERO: Self = [0.0; 3];
    const TREE_TYPE: &'static str = "Tree_vec3s_5_4_3";
    const VECTOR_TYPE: Option<&'static str> = Some("invariant");
    fn floats(values: &[Self]) -> &[f32] {
        values.as_flattened()
    }
    fn write_block(w: &mut Writer, values: &[Self], mask: &[u64], half: bool, compression: u32) {
        write_vec3s_block(w, values.as_flattened(), mask, half, compression);
    }
}

/// How a grid's index-to-world map is written.
#[derive(Clone, Copy, Debug)]
pub(super) enum GridMap {
    /// The simplest map type that holds it, in single precision (`write_transform`).
    Single(Affine3A),
    /// An AffineMap in double precision, as given.
    Double(DMat4),
}

/// A tree being assembled: leaves (VDB order, z fastest) and active 8^3 tiles, grouped as the
/// file wants them: Internal5 origin -> Internal4 slot -> leaf/tile slot.
pub(super) struct Tree<V: Voxel> {
    nodes: BTreeMap<Key, BTreeMap<usize, BTreeMap<usize, Slot<V>>>>,
    voxels: u64,
    bbox_min: IVec3,
    bbox_max: IVec3,
}

pub(super) type FloatTree = Tree<f32>;

enum Slot<V> {
    Leaf(Box<[V; 512]>, [u64; 8]),
    Tile(V),
    /// A leaf already encoded (its mask and value block, as the buffers section holds it) in
    /// a streaming writer's scratch file at `at`, `len` bytes (stream_writer.rs).
    Stored { mask: [u64; 8], at: u64, len: u64 },
}

fn i4_offset(o: IVec3) -> usize {
    let l: IVec3 = (o & IVec3::splat(4095)) >> 7;
    ((l.x as usize) << 10) | ((l.y as usize) << 5) | l.z as usize
}
fn i3_offset(o: IVec3) -> usize {
    let l: IVec3 = (o & IVec3::splat(127)) >> 3;
    ((l.x as usize) << 8) | ((l.y as usize) << 4) | l.z as usize
}

impl<V: Voxel> Tree<V> {
    pub(super) fn new() -> Self {
        Tree { nodes: BTreeMap::new(), voxels: 0, bbox_min: IVec3::MAX, bbox_max: IVec3::MIN }
    }

    fn slot(&mut self, origin: IVec3) -> &mut BTreeMap<usize, Slot<V>> {
        self.nodes.entry(key(origin & IVec3::splat(!4095))).or_default().entry(i4_offset(origin)).or_default()
    }

    /// A leaf at `origin` (multiple of 8), values z fastest. Non-zero voxels are active.
    fn add_leaf(&mut self, origin: IVec3, values: Box<[V; 512]>) {
        if let Some(mask) = self.leaf_mask(origin, &values) {
            self.slot(origin).insert(i3_offset(origin), Slot::Leaf(values, mask));
        }
    }

    /// A leaf already encoded elsewhere (see `Slot::Stored`).
    pub(super) fn add_stored(&mut self, origin: IVec3, mask: [u64; 8], at: u64, len: u64) {
        self.slot(origin).insert(i3_offset(origin), Slot::Stored { mask, at, len });
    }

    /// The active mask of a leaf's values (non-zero voxels), counted into the voxel count and
    /// bounding box; None when none is active (the leaf is left out).
    pub(super) fn leaf_mask(&mut self, origin: IVec3, values: &[V; 512]) -> Option<[u64; 8]> {
        let mut mask = [0u64; 8];
        for (i, v) in values.iter().enumerate() {
            if *v != V::ZERO {
                mask[i >> 6] |= 1 << (i & 63);
                let p = origin + IVec3::new((i >> 6) as i32, ((i >> 3) & 7) as i32, (i & 7) as i32);
                self.bbox_min = self.bbox_min.min(p);
                self.bbox_max = self.bbox_max.max(p);
                self.voxels += 1;
            }
        }
        mask.iter().any(|w| *w != 0).then_some(mask)
    }

    /// The encoded leaves (`Slot::Stored`) in the order of the buffers section.
    pub(super) fn stored(&self) -> impl Iterator<Item = (u64, u64)> + '_ {
        self.nodes.values().flat_map(|i4s| i4s.values()).flat_map(|slots| slots.values()).filter_map(|s| match s {
            Slot::Stored { at, len, .. } => Some((*at, *len)),
            _ => None,
        })
    }

    fn add_tile8(&mut self, origin: IVec3, v: V) {
        if v == V::ZERO {
            return;
        }
        self.bbox_min = self.bbox_min.min(origin);
        self.bbox_max = self.bbox_max.max(origin + IVec3::splat(7));
        self.voxels += 512;
        self.slot(origin).insert(i3_offset(origin), Slot::Tile(v));
    }

    /// A dense array, x fastest: `get(i)` is voxel `i`'s value. Non-zero voxels are active.
    pub(super) fn from_dense(dims: [u32; 3], get: impl Fn(usize) -> V) -> Self {
        let mut t = Tree::new();
        let d = [dims[0] as usize, dims[1] as usize, dims[2] as usize];
        for bz in (0..d[2]).step_by(8) {
            for by in (0..d[1]).step_by(8) {
                for bx in (0..d[0]).step_by(8) {
                    let mut zf = Box::new([V::ZERO; 512]);
                    for x in 0..8.min(d[0] - bx) {
                        for y in 0..8.min(d[1] - by) {
                            for z in 0..8.min(d[2] - bz) {
                                zf[(x << 6) | (y << 3) | z] = get((bx + x) + d[0] * ((by + y) + d[1] * (bz + z)));
                            }
                        }
                    }
                    t.add_leaf(IVec3::new(bx as i32, by as i32, bz as i32), zf);
                }
            }
        }
        t
    }
}

impl FloatTree {
    fn from_density(g: &DensityGrid) -> Self {
        let mut t = FloatTree::new();
        g.for_each_brick(|origin, b| match b {
            BrickRef::Constant(v) => t.add_tile8(origin, v),
            BrickRef::Dense(xf) => {
                let mut zf = Box::new([0.0f32; 512]);
                for x in 0..8 {
                    for y in 0..8 {
                        for z in 0..8 {
                            zf[(x << 6) | (y << 3) | z] = xf[x | (y << 3) | (z << 6)];
                        }
                    }
                }
                t.add_leaf(origin, zf);
            }
        });
        t
    }
}

pub(super) fn compression_flags(o: &WriteOptions) -> u32 {
    COMPRESS_ACTIVE_MASK | if o.compression == VdbCompression::Zip { COMPRESS_ZIP } else { 0 }
}

/// Writes one grid (descriptor and body) and patches its offsets.
pub(super) fn write_grid<V: Voxel>(w: &mut Writer, unique_name: &str, name: &str, tree: &Tree<V>, map: GridMap, o: &WriteOptions) {
    let comp = compression_flags(o);
    let (offsets_at, grid_pos) = write_grid_head(w, unique_name, name, tree, map, o);
    // Buffers, same order.
    let block_pos = w.pos();
    for i4s in tree.nodes.values() {
        for slots in i4s.values() {
            for s in slots.values() {
                if let Slot::Leaf(vals, mask) = s {
                    w.mask(mask);
                    V::write_block(w, &vals[..], mask, o.half, comp);
                }
            }
        }
    }
    let end_pos = w.pos();
    w.patch_i64(offsets_at, grid_pos as i64);
    w.patch_i64(offsets_at + 8, block_pos as i64);
    w.patch_i64(offsets_at + 16, end_pos as i64);
}

/// A grid's descriptor (offsets left 0), metadata, transform and topology: everything before
/// its buffers. Returns where the three offsets are and where the grid starts (both
/// positions in `w`).
pub(super) fn write_grid_head<V: Voxel>(w: &mut Writer, unique_name: &str, name: &str, tree: &Tree<V>, map: GridMap, o: &WriteOptions) -> (usize, usize) {
    let comp = compression_flags(o);
    w.string(unique_name);
    w.string(&format!("{}{}", V::TREE_TYPE, if o.half { header::HALF_SUFFIX } else { "" }));
    w.string(""); // instance parent
    let offsets_at = w.pos();
    w.i64(0);
    w.i64(0);
    w.i64(0);
    let grid_pos = w.pos();
    w.u32(comp);
    let mut meta: MetaMap = vec![("class".into(), MetaValue::String(o.class.clone())), ("name".into(), MetaValue::String(name.into()))];
    if let Some(t) = V::VECTOR_TYPE {
        meta.push(("vector_type".into(), MetaValue::String(t.into())));
    }
    meta.extend([
        ("is_saved_as_half_float".into(), MetaValue::Bool(o.half)),
        ("file_voxel_count".into(), MetaValue::Int(tree.voxels as i64)),
        ("creator".into(), MetaValue::String(format!("volscatter {}", crate::VERSION))),
    ]);
    if tree.voxels > 0 {
        meta.push(("file_bbox_min".into(), MetaValue::Vec3i(tree.bbox_min.to_array())));
        meta.push(("file_bbox_max".into(), MetaValue::Vec3i(tree.bbox_max.to_array())));
    }
    header::write_meta_map(w, &meta);
    match map {
        GridMap::Single(xf) => {
            write_transform(w, xf);
        }
        GridMap::Double(m) => write_affine_map(w, &m),
    }
    // Topology.
    w.i32(1); // buffer count
    for v in V::floats(&[V::ZERO]) {
        w.f32(*v); // background, full size even for half grids
    }
    w.u32(0); // root tiles
    w.u32(tree.nodes.len() as u32);
    let zeros4096 = vec![V::ZERO; 4096];
    for (&(x, y, z), i4s) in &tree.nodes {
        w.i32(x);
        w.i32(y);
        w.i32(z);
        let mut child = vec![0u64; 512];
        for &n in i4s.keys() {
            child[n >> 6] |= 1 << (n & 63);
        }
        w.mask(&child);
        let none = vec![0u64; 512];
        w.mask(&none);
        V::write_block(w, &vec![V::ZERO; 32768], &none, o.half, comp);
        for slots in i4s.values() {
            let mut child = [0u64; 64];
            let mut active = [0u64; 64];
            let mut vals = zeros4096.clone();
            for (&n, s) in slots {
                match s {
                    Slot::Leaf(..) | Slot::Stored { .. } => child[n >> 6] |= 1 << (n & 63),
                    Slot::Tile(v) => {
                        active[n >> 6] |= 1 << (n & 63);
                        vals[n] = *v;
                    }
                }
            }
            w.mask(&child);
            w.mask(&active);
            V::write_block(w, &vals, &active, o.half, comp);
            for s in slots.values() {
                if let Slot::Leaf(_, mask) | Slot::Stored { mask, .. } = s {
                    w.mask(mask);
                }
            }
        }
    }
    (offsets_at, grid_pos)
}

fn write_file(path: &Path, grids: &[(&str, FloatTree)], xf: Affine3A, o: &WriteOptions) -> Result<()> {
    let mut w = file_head(path, grids.len(), xf, o)?;
    for ((_, tree), (unique, name)) in grids.iter().zip(unique_names(grids.iter().map(|g| g.0))?) {
        write_grid(&mut w, &unique, name, tree, GridMap::Single(xf), o);
    }
    stamp_content_uuid(&mut w.buf);
    crate::io::files::write_file_atomic(path, &w.buf)
}

/// Checks the map and options, and writes the file header up to the grid count.
pub(super) fn file_head(path: &Path, grids: usize, xf: Affine3A, o: &WriteOptions) -> Result<Writer> {
    if !xf.is_finite() || glam::Mat3::from(xf.matrix3).determinant() == 0.0 {
        return Err(Error::InvalidArgument(format!("index-to-world map {xf:?} is not invertible")));
    }
    if o.class != "fog volume" && o.class != "unknown" {
        return Err(Error::InvalidArgument(format!("grid class `{}` (use \"fog volume\" or \"unknown\")", o.class)));
    }
    let mut w = Writer::default();
    w.bytes(&header::MAGIC.to_le_bytes());
    w.u32(header::WRITE_FILE_VERSION);
    w.u32(10); // library version of the format written: OpenVDB 10.0
    w.u32(0);
    w.u8(1); // grid offsets present
    w.bytes(uuid_text(path).as_bytes());
    header::write_meta_map(&mut w, &vec![("creator".into(), MetaValue::String(format!("volscatter {}", crate::VERSION)))]);
    w.i32(grids as i32);
    Ok(w)
}

/// Each grid's unique name (the name, with a suffix from its second use on) and name; an
/// empty name or one with the separator is refused.
pub(super) fn unique_names<'a>(names: impl Iterator<Item = &'a str>) -> Result<Vec<(String, &'a str)>> {
    let mut used: Vec<&str> = Vec::new();
    let mut out = Vec::new();
    for name in names {
        if name.is_empty() || name.contains(header::NAME_SEP) {
            return Err(Error::InvalidArgument(format!("grid name `{name:?}` is empty or has a \\x1e")));
        }
        let n = used.iter().filter(|u| **u == name).count();
        out.push((if n == 0 { name.to_string() } else { format!("{name}{}{n}", header::NAME_SEP) }, name));
        used.push(name);
    }
    Ok(out)
}

/// Where the 36-character UUID sits in a file: after the magic (8), three versions (12) and
/// the grid-offsets flag (1).
const UUID_AT: usize = 21;

/// Replaces the file's UUID with one made from its other bytes (two FNV-1a hashes), so that the
/// same grids give the same file byte for byte, whichever process or machine wrote it (a farm's
/// re-run frame equals the first), while files with other content still differ in UUID.
pub(super) fn stamp_content_uuid(buf: &mut [u8]) {
    let fnv = |basis: u64| {
        let rest = buf[..UUID_AT].iter().chain(&buf[UUID_AT + 36..]);
        rest.fold(basis, |h, &b| (h ^ b as u64).wrapping_mul(0x0000_0100_0000_01b3))
    };
    let (a, b) = (fnv(0xcbf2_9ce4_8422_2325), fnv(0x6c62_272e_07bb_0142));
    let s = format!("{a:016x}{b:016x}");
    let text = format!("{}-{}-{}-{}-{}", &s[0..8], &s[8..12], &s[12..16], &s[16..20], &s[20..32]);
    buf[UUID_AT..UUID_AT + 36].copy_from_slice(text.as_bytes());
}

/// 36 characters in UUID form; unique enough to tell files apart.
fn uuid_text(path: &Path) -> String {
    use std::hash::{BuildHasher, Hash, Hasher};
    let mut h = std::collections::hash_map::RandomState::new().build_hasher();
    path.hash(&mut h);
    std::time::SystemTime::now().hash(&mut h);
    let a = h.finish();
    a.hash(&mut h);
    let b = h.finish();
    let s = format!("{a:016x}{b:016x}");
    format!("{}-{}-{}-{}-{}", &s[0..8], &s[8..12], &s[12..16], &s[16..20], &s[20..32])
}

/// Writes a density grid as one float grid named `name`.
pub fn write_float_grid(path: &Path, name: &str, grid: &DensityGrid, index_to_world: Affine3A, options: &WriteOptions) -> Result<()> {
    write_file(path, &[(name, FloatTree::from_density(grid))], index_to_world, options)
}

pub(super) fn check_dense(dims: [u32; 3], len: usize, what: &str) -> Result<()> {
    let n = dims[0] as u64 * dims[1] as u64 * dims[2] as u64;
    if n != len as u64 {
        return Err(Error::InvalidArgument(format!(
            "{what}: dims {}x{}x{} need {n} values, got {len}",
            dims[0], dims[1], dims[2]
        )));
    }
    if dims.iter().any(|&d| d > i32::MAX as u32 - 8) {
        return Err(Error::InvalidArgument(format!("{what}: dims {dims:?} too large")));
    }
    Ok(())
}

/// Writes dense float arrays (x fastest, sharing one index-to-world map) as float grids.
pub fn write_dense_float_grids(path: &Path, grids: &[DenseFloat<'_>], index_to_world: Affine3A, options: &WriteOptions) -> Result<()> {
    let mut trees = Vec::new();
    for g in grids {
        check_dense(g.dims, g.values.len(), g.name)?;
        if let Some(i) = g.values.iter().position(|v| !v.is_finite()) {
            return Err(Error::InvalidArgument(format!("{}: value {i} is {}", g.name, g.values[i])));
        }
        trees.push((g.name, FloatTree::from_dense(g.dims, |i| g.values[i])));
    }
    write_file(path, &trees, index_to_world, options)
}

/// Writes a dense RGB array (x fastest; e.g. the scattering grid) as three float grids
/// `<prefix>_r`, `<prefix>_g`, `<prefix>_b`.
pub fn write_rgb_grids(path: &Path, prefix: &str, dims: [u32; 3], data: &[Vec3], index_to_world: Affine3A, options: &WriteOptions) -> Result<()> {
    check_dense(dims, data.len(), prefix)?;
    if let Some(i) = data.iter().position(|v| !v.is_finite()) {
        return Err(Error::InvalidArgument(format!("{prefix}: value {i} is {}", data[i])));
    }
    let names = [format!("{prefix}_r"), format!("{prefix}_g"), format!("{prefix}_b")];
    let trees: Vec<(&str, FloatTree)> =
        (0..3).map(|c| (names[c].as_str(), FloatTree::from_dense(dims, |i| data[i][c]))).collect();
    write_file(path, &trees, index_to_world, options)
}

/// Writes a density grid through the dense writer: the grid's bounding box as one dense
/// array, index (0,0,0) at the box's minimum corner, the transform moved to match. For
/// testing the dense path against OpenVDB; refuses boxes over 2^28 voxels.
pub fn write_density_as_dense(path: &Path, name: &str, grid: &DensityGrid, index_to_world: Affine3A, options: &WriteOptions) -> Result<()> {
    let (lo, hi) = if grid.is_empty() { (IVec3::ZERO, IVec3::ZERO) } else { grid.bbox() };
    let d = (hi - lo + IVec3::ONE).as_i64vec3();
    let n = d.x * d.y * d.z;
    if n > 1 << 28 {
        return Err(Error::TooLarge(format!("dense copy of {} x {} x {} voxels", d.x, d.y, d.z)));
    }
    let mut values = Vec::with_capacity(n as usize);
    for z in lo.z..=hi.z {
        for y in lo.y..=hi.y {
            for x in lo.x..=hi.x {
                values.push(grid.voxel(IVec3::new(x, y, z)));
            }
        }
    }
    let dims = [d.x as u32, d.y as u32, d.z as u32];
    let xf = index_to_world * Affine3A::from_translation(lo.as_vec3());
    write_dense_float_grids(path, &[DenseFloat { name, dims, values: &values }], xf, options)
}
