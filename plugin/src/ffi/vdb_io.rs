//! OpenVDB files for hosts: what a host needs to list the grids of a VDB and to write grids of
//! its own, so that no host carries a VDB reader or writer beside the library's (the USD bake
//! writes its scattering fields through `vs_vdb_write_grids`, its stage reader lists fields
//! with `vs_vdb_info_json`).
//!
//! Both calls take a scene only to carry their error message (`vs_scene_last_error`), as
//! `vs_scene_lpm_estimate` does; the scene is not read or changed.
//!
//! Writing: float grids go through core's writer (`vdb::write_dense_float_grids`: file
//! version 224, Zip, active mask). The core writer has no vec3s grids and no grid copies, so
//! those are assembled here: a vec3s grid's tree is encoded beside the float ones (same
//! 5-4-3 layout, active-mask compression, values uncompressed), and a copied grid's bytes are
//! taken verbatim from a version-224 file (a grid's bytes hold no absolute offsets). The file
//! is written to a temporary beside `path` and renamed over it, so `path` is either the old
//! file or the whole new one.

use std::collections::BTreeMap;
use std::ffi::{c_char, CString};
use std::io::{Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

use glam::{Affine3A, DMat4, DVec4, IVec3};
use serde_json::json;
use volscatter_core::vdb::{self, header, DenseFloat, VdbFile, WriteOptions};

use super::guard::{in_slice, input_file_arg, on_handle, opt_str_arg, path_arg, str_arg, write_out};
use super::scene::{VsScene, SCENES};
use super::status::{FfiError, FfiResult, VsStatus};

/// `vs_vdb_info_json` flag: also read every grid's tree for its statistics (bounding box,
/// active voxels, sum of values, metadata), as `volscatter vdb-info` prints them. Without it
/// only the file's header and grid descriptors are read.
pub const VS_VDB_INFO_STATS: u32 = 1;

/// One grid for `vs_vdb_write_grids`: `components` 1 (a float grid) or 3 (a vec3s grid) values
/// per voxel, `len == nx * ny * nz * components` finite floats, x fastest then y then z (a vec3s
/// voxel's three values together). Voxel (i, j, k) is active when any of its values is not 0.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct VsVdbGrid {
    /// Grid name: UTF-8, not empty, without the character 0x1E.
    pub name: *const c_char,
    pub components: u32,
    pub values: *const f32,
    pub len: usize,
}

/// One grid copied byte for byte into the file `vs_vdb_write_grids` writes: grid
/// `source_grid` (its name or unique name; NULL: `name`) of the OpenVDB file `source_path`,
/// which must be file version 224 (what volscatter and current OpenVDB write) and not an
/// instance grid; it keeps its own transform, values and metadata (OpenVDB names a grid by
/// its `name` metadata when it has one: `name` is the descriptor's name, which volscatter
/// reads, and a renamed copy may show its old name in OpenVDB).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct VsVdbGridCopy {
    /// Name of the grid in the new file.
    pub name: *const c_char,
    pub source_path: *const c_char,
    pub source_grid: *const c_char,
}

/// Largest voxel count per axis of a caller's grid (keeps index arithmetic in i32).
const MAX_SIDE: u32 = 1 << 16;
/// Largest source file read for a copy, and largest file listed.
const MAX_FILE_BYTES: u64 = 1 << 40;

fn with_scene(scene: *mut VsScene, body: impl FnOnce() -> FfiResult) -> VsStatus {
    on_handle(&SCENES, scene, |_| body())
}

/// Writes into the caller's buffer `buf` of `len` bytes the JSON describing the OpenVDB file
/// at `path` (UTF-8, NUL-terminated), and sets `*needed` to its size in bytes, NUL included.
/// Call with `buf` NULL and `len` 0 to get `*needed` only; then call again with a buffer of
/// exactly `*needed` bytes (any other length: `VS_STATUS_BUFFER_SIZE`, `*needed` still set).
/// The JSON: `{"file", "file_version", "library_version", "grids": [{"name", "unique_name",
/// "value_type" ("float", "vec3s", ...), "tree_type", "half", "instance_parent" (or null)},
/// ...]}` in file order; with `VS_VDB_INFO_STATS` in `flags` each grid also has what
/// `volscatter vdb-info` prints ("class", "compression", "transform", "index_to_world",
/// "bbox_min", "bbox_max", "active_voxels", "sum", "metadata"). Other flag bits are refused.
/// Errors (missing file: `VS_STATUS_IO`; not a VDB: `VS_STATUS_FORMAT`) are recorded on
/// `scene` for `vs_scene_last_error`; the scene is not changed.
///
/// Thread safety: any thread; calls on one scene are serialised.
#[no_mangle]
pub unsafe extern "C" fn vs_vdb_info_json(
    scene: *mut VsScene,
    path: *const c_char,
    flags: u32,
    buf: *mut c_char,
    len: usize,
    needed: *mut usize,
) -> VsStatus {
    with_scene(scene, || {
        write_out(needed, 0, "needed")?;
        if flags & !VS_VDB_INFO_STATS != 0 {
            return Err(FfiError::invalid(format!("flags {flags:#x}: unknown bits {:#x} (VS_VDB_INFO_STATS 1)", flags & !VS_VDB_INFO_STATS)));
        }
        if buf.is_null() && len != 0 {
            return Err(FfiError::null("buf"));
        }
        let path = input_file_arg(path, "path", MAX_FILE_BYTES)?;
        let text = info_json(&path, flags & VS_VDB_INFO_STATS != 0)?;
        let c = CString::new(text).map_err(|_| FfiError::new(VsStatus::Internal, "the VDB info JSON contains a NUL byte"))?;
        let bytes = c.as_bytes_with_nul();
        write_out(needed, bytes.len(), "needed")?;
        if buf.is_null() {
            return Ok(());
        }
        if len != bytes.len() {
            return Err(FfiError::buffer(format!("buf holds {len} bytes; the JSON needs exactly {} (NUL included)", bytes.len())));
        }
        std::ptr::copy_nonoverlapping(bytes.as_ptr().cast::<c_char>(), buf, bytes.len());
        Ok(())
    })
}

fn info_json(path: &Path, stats: bool) -> FfiResult<String> {
    if stats {
        let info = vdb::inspect(path)?;
        return serde_json::to_string(&info).map_err(|e| FfiError::new(VsStatus::Internal, format!("VDB info JSON: {e}")));
    }
    let f = VdbFile::open(path, MAX_FILE_BYTES)?;
    let grids: Vec<_> = f
        .grids
        .iter()
        .map(|g| {
            json!({
                "name": g.name,
                "unique_name": g.unique_name,
                "value_type": vdb::values::ValueKind::type_name(&g.grid_type),
                "tree_type": g.grid_type,
                "half": g.half,
                "instance_parent": (!g.instance_parent.is_empty()).then(|| g.instance_parent.clone()),
            })
        })
        .collect();
    Ok(json!({
        "file": path.display().to_string(),
        "file_version": f.header.version,
        "library_version": format!("{}.{}", f.header.library_major, f.header.library_minor),
        "grids": grids,
    })
    .to_string())
}

/// Writes a new OpenVDB file (version 224) at `path` holding, in this order, the `copy_count`
/// grids of `copies` (copied byte for byte, see `VsVdbGridCopy`) and the `grid_count` grids of
/// `grids` (see `VsVdbGrid`), the latter all of `dims` (3 values nx, ny, nz, each 1..=65536)
/// voxels placed by `index_to_world` (16 doubles, row-major 4x4 affine, invertible, each finite
/// in single precision): voxel (i, j, k) sits at `index_to_world * (i, j, k, 1)`. Float grids
/// are written by the library's VDB writer (Zip; their map in single precision, as every grid
/// it writes); vec3s grids uncompressed, with the map as given. Names must be unique in the file. `grids` may be
/// NULL when `grid_count` is 0 and `copies` when `copy_count` is 0; at least one grid is
/// needed. The file is written beside `path` and renamed over it: on failure `path` is left as
/// it was. Errors are recorded on `scene` for `vs_scene_last_error`; the scene is not changed.
///
/// Thread safety: any thread; calls on one scene are serialised.
#[no_mangle]
pub unsafe extern "C" fn vs_vdb_write_grids(
    scene: *mut VsScene,
    path: *const c_char,
    dims: *const u32,
    index_to_world: *const f64,
    grids: *const VsVdbGrid,
    grid_count: usize,
    copies: *const VsVdbGridCopy,
    copy_count: usize,
) -> VsStatus {
    with_scene(scene, || {
        let path = path_arg(path, "path")?;
        let grids: &[VsVdbGrid] = if grid_count == 0 { &[] } else { in_slice(grids, grid_count, "grids")? };
        let copies: &[VsVdbGridCopy] = if copy_count == 0 { &[] } else { in_slice(copies, copy_count, "copies")? };
        if grids.is_empty() && copies.is_empty() {
            return Err(FfiError::invalid("no grids to write (grid_count and copy_count are 0)"));
        }
        // Every argument is checked before anything is read or allocated.
        let dims = dims_arg(dims)?;
        let (m, xf) = affine_arg(index_to_world, "index_to_world")?;
        let voxels = dims.iter().map(|&d| d as u64).product::<u64>();
        let mut names: Vec<&str> = Vec::new();
        let mut checked = Vec::with_capacity(grids.len());
        for (i, g) in grids.iter().enumerate() {
            let name = str_arg(g.name, &format!("grids[{i}].name"))?;
            if g.components != 1 && g.components != 3 {
                return Err(FfiError::invalid(format!("grids[{i}] `{name}`: components {} (1: float, 3: vec3s)", g.components)));
            }
            let want = voxels.checked_mul(g.components as u64).filter(|&n| n <= usize::MAX as u64);
            if want != Some(g.len as u64) {
                return Err(FfiError::buffer(format!(
                    "grids[{i}] `{name}` holds {} values; dims {}x{}x{} with {} component(s) need {}",
                    g.len, dims[0], dims[1], dims[2], g.components, voxels.saturating_mul(g.components as u64)
                )));
            }
            let values = in_slice(g.values, g.len, &format!("grids[{i}].values"))?;
            if let Some(k) = values.iter().position(|v| !v.is_finite()) {
                return Err(FfiError::invalid(format!("grids[{i}] `{name}`: value {k} is {}", values[k])));
            }
            names.push(name);
            checked.push((name, g.components, values));
        }
        let mut sources = Vec::with_capacity(copies.len());
        for (i, c) in copies.iter().enumerate() {
            let name = str_arg(c.name, &format!("copies[{i}].name"))?;
            let src = input_file_arg(c.source_path, &format!("copies[{i}].source_path"), MAX_FILE_BYTES)?;
            let grid = opt_str_arg(c.source_grid, &format!("copies[{i}].source_grid"))?.unwrap_or(name);
            names.push(name);
            sources.push((name, src, grid));
        }
        for (i, n) in names.iter().enumerate() {
            if n.is_empty() || n.contains('\u{1e}') {
                return Err(FfiError::invalid(format!("grid name {n:?} is empty or has the character 0x1E")));
            }
            if names[..i].contains(n) {
                return Err(FfiError::invalid(format!("grid name `{n}` is used twice")));
            }
        }

        let mut out = Vec::new();
        for (name, src, grid) in &sources {
            out.push(copied_grid(name, src, grid)?);
        }
        let floats: Vec<_> = checked.iter().filter(|g| g.1 == 1).collect();
        let mut float_parts = if floats.is_empty() {
            Vec::new()
        } else {
            let dense: Vec<DenseFloat> = floats.iter().map(|g| DenseFloat { name: g.0, dims, values: g.2 }).collect();
            let scratch = Scratch::beside(&path);
            vdb::write_dense_float_grids(&scratch.0, &dense, xf, &WriteOptions::default())?;
            grids_of(&scratch.0, None)?
        };
        float_parts.reverse();
        for (name, comps, values) in &checked {
            if *comps == 1 {
                out.push(float_parts.pop().ok_or_else(|| FfiError::new(VsStatus::Internal, format!("float grid `{name}` was not written")))?);
            } else {
                out.push(vec3s_grid(name, dims, values, &m));
            }
        }
        let bytes = assemble(&path, &out);
        let tmp = Scratch::beside(&path);
        volscatter_core::io::files::write_file(&tmp.0, &bytes)?;
        std::fs::rename(&tmp.0, &path).map_err(|e| FfiError::new(VsStatus::Io, format!("{}: {e}", path.display())))?;
        std::mem::forget(tmp); // renamed: nothing left to remove
        Ok(())
    })
}

/// `nx, ny, nz`, each in 1..=MAX_SIDE.
unsafe fn dims_arg(p: *const u32) -> FfiResult<[u32; 3]> {
    if p.is_null() {
        return Err(FfiError::null("dims"));
    }
    let d = [p.read_unaligned(), p.add(1).read_unaligned(), p.add(2).read_unaligned()];
    if d.iter().any(|&n| n == 0 || n > MAX_SIDE) {
        return Err(FfiError::invalid(format!("dims {d:?}: each must be in 1..={MAX_SIDE}")));
    }
    Ok(d)
}

/// 16 doubles, row-major, an invertible affine map (last row 0 0 0 1) that is finite in single
/// precision: the doubles as given and the map in single precision.
unsafe fn affine_arg(p: *const f64, what: &str) -> FfiResult<(DMat4, Affine3A)> {
    if p.is_null() {
        return Err(FfiError::null(what));
    }
    let mut m = [0.0f64; 16];
    for (i, v) in m.iter_mut().enumerate() {
        // Unaligned reads: a host may pass doubles packed in a byte buffer.
        *v = p.add(i).read_unaligned();
        if !(*v as f32).is_finite() {
            return Err(FfiError::invalid(format!("{what}[{i}] is {v}: must be finite in single precision")));
        }
    }
    let mat = DMat4::from_cols_array(&m).transpose();
    if !mat.row(3).abs_diff_eq(DVec4::W, 1e-6) {
        return Err(FfiError::invalid(format!("{what}: last row must be 0 0 0 1 (row-major affine matrix), got {:?}", mat.row(3).to_array())));
    }
    let single = mat.as_mat4();
    let det = single.determinant();
    if !(det.is_finite() && det.abs() > 1e-12) {
        return Err(FfiError::invalid(format!("{what}: matrix is not invertible (determinant {det})")));
    }
    Ok((mat, Affine3A::from_mat4(single)))
}

/// A temporary file beside a target (same folder, so a rename replaces the target), removed
/// when dropped.
struct Scratch(PathBuf);

impl Scratch {
    fn beside(target: &Path) -> Self {
        static N: AtomicUsize = AtomicUsize::new(0);
        let n = N.fetch_add(1, Ordering::Relaxed);
        let name = target.file_name().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
        Scratch(target.with_file_name(format!(".{name}.{}-{n}.tmp", std::process::id())))
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}

/// A grid ready to be placed in a file: its descriptor's name and tree type, and its bytes
/// from the grid's start to its end, with the buffers starting at `block` within them.
struct GridPart {
    name: String,
    tree_type: String,
    body: Vec<u8>,
    block: u64,
}

/// Every grid of a version-224 file (or only the one named `only`) as parts to copy.
fn grids_of(path: &Path, only: Option<&str>) -> FfiResult<Vec<GridPart>> {
    let f = VdbFile::open(path, MAX_FILE_BYTES)?;
    let io = |e: std::io::Error| FfiError::new(VsStatus::Io, format!("{}: {e}", path.display()));
    let mut file = std::fs::File::open(path).map_err(io)?;
    let mut out = Vec::new();
    for g in &f.grids {
        if only.is_some_and(|n| n != g.name && n != g.unique_name) {
            continue;
        }
        if f.header.version != header::WRITE_FILE_VERSION {
            return Err(FfiError::new(
                VsStatus::Unsupported,
                format!("{}: file version {} (a grid is copied byte for byte from version {} files only)", path.display(), f.header.version, header::WRITE_FILE_VERSION),
            ));
        }
        if !g.instance_parent.is_empty() || g.block_pos == 0 {
            return Err(FfiError::new(VsStatus::Unsupported, format!("{}: grid `{}` is an instance of `{}`; it cannot be copied", path.display(), g.name, g.instance_parent)));
        }
        // The offsets were checked against the file's size when it was opened; only the
        // grid's own bytes are read.
        let len = (g.end_pos - g.grid_pos) as u64;
        volscatter_core::budget::check(&format!("grid `{}` of {}", g.name, path.display()), len)?;
        let mut body = vec![0u8; len as usize];
        file.seek(SeekFrom::Start(g.grid_pos as u64)).map_err(io)?;
        file.read_exact(&mut body).map_err(io)?;
        let tree_type = if g.half { format!("{}_HalfFloat", g.grid_type) } else { g.grid_type.clone() };
        out.push(GridPart { name: g.unique_name.clone(), tree_type, body, block: (g.block_pos - g.grid_pos) as u64 });
        if only.is_some() {
            break;
        }
    }
    Ok(out)
}

fn copied_grid(name: &str, src: &Path, grid: &str) -> FfiResult<GridPart> {
    let mut parts = grids_of(src, Some(grid))?;
    let mut part = parts.pop().ok_or_else(|| {
        FfiError::new(VsStatus::Format, format!("{}: no grid named `{grid}`", src.display()))
    })?;
    part.name = name.to_string();
    Ok(part)
}

/// Little-endian bytes, as OpenVDB files hold them.
#[derive(Default)]
struct Bytes(Vec<u8>);

impl Bytes {
    fn put(&mut self, b: &[u8]) {
        self.0.extend_from_slice(b);
    }
    fn u8(&mut self, v: u8) {
        self.0.push(v);
    }
    fn u32(&mut self, v: u32) {
        self.put(&v.to_le_bytes());
    }
    fn i32(&mut self, v: i32) {
        self.put(&v.to_le_bytes());
    }
    fn i64(&mut self, v: i64) {
        self.put(&v.to_le_bytes());
    }
    fn f32(&mut self, v: f32) {
        self.put(&v.to_le_bytes());
    }
    fn string(&mut self, s: &str) {
        self.u32(s.len() as u32);
        self.put(s.as_bytes());
    }
    fn mask(&mut self, words: &[u64]) {
        for w in words {
            self.put(&w.to_le_bytes());
        }
    }
    fn meta_string(&mut self, k: &str, v: &str) {
        self.string(k);
        self.string("string");
        self.string(v);
    }
}

/// The whole file: header, file metadata, then each grid's descriptor and bytes.
fn assemble(path: &Path, grids: &[GridPart]) -> Vec<u8> {
    let mut w = Bytes::default();
    w.put(&header::MAGIC.to_le_bytes());
    w.u32(header::WRITE_FILE_VERSION);
    w.u32(10); // library version of the format written: OpenVDB 10.0, as core's writer
    w.u32(0);
    w.u8(1); // grid offsets present
    w.put(uuid_text(path).as_bytes());
    w.u32(1);
    w.meta_string("creator", &format!("volscatter {}", volscatter_core::VERSION));
    w.i32(grids.len() as i32);
    for g in grids {
        w.string(&g.name);
        w.string(&g.tree_type);
        w.string(""); // instance parent
        let start = (w.0.len() + 24) as i64;
        w.i64(start);
        w.i64(start + g.block as i64);
        w.i64(start + g.body.len() as i64);
        w.put(&g.body);
    }
    w.0
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

/// A leaf: active mask and the active voxels' values (3 each), VDB order (z fastest).
type Leaf = ([u64; 8], Vec<f32>);

/// A dense vec3s grid (x fastest, 3 values a voxel) as a 5-4-3 tree: active-mask compression,
/// metadata 0 blocks (every inactive value is the background 0), values uncompressed.
fn vec3s_grid(name: &str, dims: [u32; 3], values: &[f32], m: &DMat4) -> GridPart {
    let d = dims.map(|n| n as usize);
    let mut nodes: BTreeMap<(i32, i32, i32), BTreeMap<usize, BTreeMap<usize, Leaf>>> = BTreeMap::new();
    let (mut voxels, mut lo, mut hi) = (0u64, IVec3::MAX, IVec3::MIN);
    for bx in (0..d[0]).step_by(8) {
        for by in (0..d[1]).step_by(8) {
            for bz in (0..d[2]).step_by(8) {
                let mut mask = [0u64; 8];
                let mut vals = Vec::new();
                for x in 0..8.min(d[0] - bx) {
                    for y in 0..8.min(d[1] - by) {
                        for z in 0..8.min(d[2] - bz) {
                            let at = 3 * ((bx + x) + d[0] * ((by + y) + d[1] * (bz + z)));
                            let v = &values[at..at + 3];
                            if v.iter().all(|c| *c == 0.0) {
                                continue;
                            }
                            let i = (x << 6) | (y << 3) | z;
                            mask[i >> 6] |= 1 << (i & 63);
                            let p = IVec3::new((bx + x) as i32, (by + y) as i32, (bz + z) as i32);
                            lo = lo.min(p);
                            hi = hi.max(p);
                            voxels += 1;
                        }
                    }
                }
                if mask.iter().all(|w| *w == 0) {
                    continue;
                }
                // Values in VDB order: the mask's set bits, ascending.
                for i in 0..512usize {
                    if mask[i >> 6] >> (i & 63) & 1 == 1 {
                        let (x, y, z) = (i >> 6, (i >> 3) & 7, i & 7);
                        let at = 3 * ((bx + x) + d[0] * ((by + y) + d[1] * (bz + z)));
                        vals.extend_from_slice(&values[at..at + 3]);
                    }
                }
                let o = IVec3::new(bx as i32, by as i32, bz as i32);
                let o5 = o & IVec3::splat(!4095);
                let l4: IVec3 = (o & IVec3::splat(4095)) >> 7;
                let l3: IVec3 = (o & IVec3::splat(127)) >> 3;
                let i4 = ((l4.x as usize) << 10) | ((l4.y as usize) << 5) | l4.z as usize;
                let i3 = ((l3.x as usize) << 8) | ((l3.y as usize) << 4) | l3.z as usize;
                nodes.entry((o5.x, o5.y, o5.z)).or_default().entry(i4).or_default().insert(i3, (mask, vals));
            }
        }
    }
    let mut w = Bytes::default();
    w.u32(header::COMPRESS_ACTIVE_MASK);
    // Grid metadata, as core's writer gives its float grids (class "unknown": not a fog volume).
    let mut meta = Bytes::default();
    let mut count = 0u32;
    for (k, v) in [("class", "unknown"), ("name", name), ("vector_type", "invariant")] {
        meta.meta_string(k, v);
        count += 1;
    }
    meta.string("is_saved_as_half_float");
    meta.string("bool");
    meta.u32(1);
    meta.u8(0);
    meta.string("file_voxel_count");
    meta.string("int64");
    meta.u32(8);
    meta.i64(voxels as i64);
    meta.meta_string("creator", &format!("volscatter {}", volscatter_core::VERSION));
    count += 3;
    if voxels > 0 {
        for (k, v) in [("file_bbox_min", lo), ("file_bbox_max", hi)] {
            meta.string(k);
            meta.string("vec3i");
            meta.u32(12);
            for c in v.to_array() {
                meta.i32(c);
            }
            count += 1;
        }
    }
    w.u32(count);
    w.put(&meta.0);
    // Transform: an AffineMap (OpenVDB's row-vector matrix: ours, column-major), in double
    // precision as given.
    w.string("AffineMap");
    for v in m.to_cols_array() {
        w.put(&v.to_le_bytes());
    }
    // Topology.
    w.i32(1); // buffer count
    for _ in 0..3 {
        w.f32(0.0); // background
    }
    w.u32(0); // root tiles
    w.u32(nodes.len() as u32);
    for (&(x, y, z), i4s) in &nodes {
        w.i32(x);
        w.i32(y);
        w.i32(z);
        let mut child = vec![0u64; 512];
        for &n in i4s.keys() {
            child[n >> 6] |= 1 << (n & 63);
        }
        w.mask(&child);
        w.mask(&[0u64; 512]);
        w.u8(0); // values: metadata 0, none active
        for leaves in i4s.values() {
            let mut child = [0u64; 64];
            for &n in leaves.keys() {
                child[n >> 6] |= 1 << (n & 63);
            }
            w.mask(&child);
            w.mask(&[0u64; 64]);
            w.u8(0);
            for (mask, _) in leaves.values() {
                w.mask(mask);
            }
        }
    }
    let block = w.0.len() as u64;
    for i4s in nodes.values() {
        for leaves in i4s.values() {
            for (mask, vals) in leaves.values() {
                w.mask(mask);
                w.u8(0);
                for v in vals {
                    w.f32(*v);
                }
            }
        }
    }
    GridPart { name: name.to_string(), tree_type: "Tree_vec3s_5_4_3".into(), body: w.0, block }
}
