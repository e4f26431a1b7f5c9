//! OpenVDB files for hosts: what a host needs to list the grids of a VDB and to write grids of
//! its own, so that no host carries a VDB reader or writer beside the library's (the USD bake
//! writes its scattering fields through `vs_vdb_write_grids`, its stage reader lists fields
//! with `vs_vdb_info_json`).
//!
//! Both calls take a scene only to carry their error message (`vs_scene_last_error`), as
//! `vs_scene_lpm_estimate` does; the scene is not read or changed.
//!
//! Writing: the arguments are checked and converted here, then written by core's VDB writer
//! in one call (`vdb::write_grids`: float and vec3s grids from the caller's arrays, grids
//! copied byte for byte from version-224 files, written atomically).

use std::ffi::{c_char, CString};
use std::path::Path;

use glam::{DMat4, DVec4};
use serde_json::json;
use volscatter_core::vdb::{self, DenseFloat, DenseVec3s, GridCopy, GridSource, VdbFile, WriteOptions};

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
        let m = affine_arg(index_to_world, "index_to_world")?;
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

        // Copies first, then the caller's grids, each in the caller's order.
        let mut out: Vec<GridSource> = sources.iter().map(|(name, source, grid)| GridSource::Copy(GridCopy { name, source, grid })).collect();
        for &(name, comps, values) in &checked {
            out.push(if comps == 1 { GridSource::Float(DenseFloat { name, dims, values }) } else { GridSource::Vec3s(DenseVec3s { name, dims, values }) });
        }
        Ok(vdb::write_grids(&path, &out, m, &WriteOptions::default())?)
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
/// precision (float grids hold their map in single precision).
unsafe fn affine_arg(p: *const f64, what: &str) -> FfiResult<DMat4> {
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
    Ok(mat)
}
