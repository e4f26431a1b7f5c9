//! Writes a dense RGB grid (three float grids `<prefix>_r/_g/_b`, as [`super::write_rgb_grids`];
//! [`RgbVdbStream`]) or a dense float grid ([`FloatVdbStream`], as [`super::write_float_grid`]
//! of the same values) z-planes at a time, for grids too large to hold: each row of leaves (8 planes) is encoded
//! as soon as its planes have arrived and appended to a scratch file beside the output; only
//! the topology (an origin and a mask a leaf) stays in memory. `finish` writes the header and
//! each grid's topology, then copies the encoded leaves in the order the format wants them
//! (topology order, which is not arrival order) and patches the grid offsets. The file is the
//! same, byte for byte, as `write_rgb_grids` of the whole array (but for the random UUID).
//!
//! The output is written to `<path>.part` and renamed when complete; the scratch file and a
//! partial output are removed on every error and when the writer is dropped unfinished.

use std::fs::{File, OpenOptions};
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use glam::{Affine3A, IVec3, Vec3};

use super::bytes::{read_exact_at, Writer};
use super::values::write_float_block;
use super::writer::{compression_flags, file_head, unique_names, write_grid_head, FloatTree, GridMap, WriteOptions};
use crate::error::{Error, Result};

/// The grids of either stream: `k` values a voxel (one per grid), interleaved.
struct PlaneStream {
    path: PathBuf,
    names: Vec<String>,
    dims: [usize; 3],
    xf: Affine3A,
    options: WriteOptions,
    scratch_path: PathBuf,
    scratch: BufWriter<File>,
    scratch_len: u64,
    trees: Vec<FloatTree>,
    /// Planes received and not yet encoded (fewer than 8, x fastest, `k` values a voxel).
    pending: Vec<f32>,
    /// The z of `pending`'s first plane.
    z: usize,
    done: bool,
}

/// S as three float grids, z-planes at a time (see the module docs).
pub struct RgbVdbStream(PlaneStream);

/// One float grid, z-planes at a time (see the module docs): e.g. a procedural medium larger
/// than memory, written slab by slab.
pub struct FloatVdbStream(PlaneStream);

impl RgbVdbStream {
    pub fn create(path: &Path, prefix: &str, dims: [u32; 3], index_to_world: Affine3A, options: &WriteOptions) -> Result<Self> {
        let names = vec![format!("{prefix}_r"), format!("{prefix}_g"), format!("{prefix}_b")];
        PlaneStream::create(path, prefix, names, dims, index_to_world, options).map(RgbVdbStream)
    }

    /// The next whole z-planes (x fastest), in order.
    pub fn push_planes(&mut self, data: &[Vec3]) -> Result<()> {
        if let Some(i) = data.iter().position(|v| !v.is_finite()) {
            return Err(Error::InvalidArgument(format!("{}: value {i} of the planes is {}", self.0.path.display(), data[i])));
        }
        let flat: Vec<f32> = data.iter().flat_map(|v| v.to_array()).collect();
        self.0.push_planes(&flat)
    }

    /// Writes the file once every plane has been pushed.
    pub fn finish(self) -> Result<()> {
        self.0.finish()
    }
}

impl FloatVdbStream {
    pub fn create(path: &Path, name: &str, dims: [u32; 3], index_to_world: Affine3A, options: &WriteOptions) -> Result<Self> {
        PlaneStream::create(path, name, vec![name.to_string()], dims, index_to_world, options).map(FloatVdbStream)
    }

    /// The next whole z-planes (x fastest), in order.
    pub fn push_planes(&mut self, data: &[f32]) -> Result<()> {
        if let Some(i) = data.iter().position(|v| !v.is_finite()) {
            return Err(Error::InvalidArgument(format!("{}: value {i} of the planes is {}", self.0.path.display(), data[i])));
        }
        self.0.push_planes(data)
    }

    /// Writes the file once every plane has been pushed.
    pub fn finish(self) -> Result<()> {
        self.0.finish()
    }
}

fn part(path: &Path, suffix: &str) -> PathBuf {
    let mut s = path.as_os_str().to_owned();
    s.push(suffix);
    PathBuf::from(s)
}

impl PlaneStream {
    fn create(path: &Path, what: &str, names: Vec<String>, dims: [u32; 3], index_to_world: Affine3A, options: &WriteOptions) -> Result<Self> {
        if dims.iter().any(|&d| d == 0 || d > i32::MAX as u32 - 8) {
            return Err(Error::InvalidArgument(format!("{what}: dims {dims:?} out of range")));
        }
        // The map, class and names are checked now, not after the solve.
        file_head(path, names.len(), index_to_world, options)?;
        unique_names(names.iter().map(|s| s.as_str()))?;
        let scratch_path = part(path, ".leaves");
        let file = OpenOptions::new().write(true).create(true).truncate(true).open(&scratch_path).map_err(|e| Error::io(&scratch_path, e))?;
        Ok(PlaneStream {
            path: path.to_path_buf(),
            trees: names.iter().map(|_| FloatTree::new()).collect(),
            names,
            dims: dims.map(|d| d as usize),
            xf: index_to_world,
            options: options.clone(),
            scratch_path,
            scratch: BufWriter::new(file),
            scratch_len: 0,
            pending: Vec::new(),
            z: 0,
            done: false,
        })
    }

    /// The next whole z-planes, `k` values a voxel (checked finite by the caller).
    fn push_planes(&mut self, data: &[f32]) -> Result<()> {
        let plane = self.dims[0] * self.dims[1] * self.names.len();
        if !data.len().is_multiple_of(plane) || self.z + (self.pending.len() + data.len()) / plane > self.dims[2] {
            return Err(Error::InvalidArgument(format!("{}: {} values are not whole planes within {:?}", self.path.display(), data.len() / self.names.len(), self.dims)));
        }
        self.pending.extend_from_slice(data);
        while self.pending.len() >= 8 * plane {
            self.encode_row(8)?;
        }
        Ok(())
    }

    /// Encodes the leaves of the first `planes` pending planes (8, or the last row's rest).
    fn encode_row(&mut self, planes: usize) -> Result<()> {
        let [nx, ny, _] = self.dims;
        let k = self.names.len();
        let plane = nx * ny;
        let comp = compression_flags(&self.options);
        for by in (0..ny).step_by(8) {
            for bx in (0..nx).step_by(8) {
                let origin = IVec3::new(bx as i32, by as i32, self.z as i32);
                for (c, tree) in self.trees.iter_mut().enumerate() {
                    let mut zf = Box::new([0.0f32; 512]);
                    for x in 0..8.min(nx - bx) {
                        for y in 0..8.min(ny - by) {
                            for z in 0..planes {
                                zf[(x << 6) | (y << 3) | z] = self.pending[k * ((bx + x) + nx * (by + y) + plane * z) + c];
                            }
                        }
                    }
                    let Some(mask) = tree.leaf_mask(origin, &zf) else { continue };
                    let mut w = Writer::default();
                    w.mask(&mask);
                    write_float_block(&mut w, &zf[..], &mask, self.options.half, comp);
                    self.scratch.write_all(&w.buf).map_err(|e| Error::io(&self.scratch_path, e))?;
                    tree.add_stored(origin, mask, self.scratch_len, w.buf.len() as u64);
                    self.scratch_len += w.buf.len() as u64;
                }
            }
        }
        self.pending.drain(..planes * plane * k);
        self.z += planes;
        Ok(())
    }

    /// Writes the file once every plane has been pushed.
    fn finish(mut self) -> Result<()> {
        let plane = self.dims[0] * self.dims[1] * self.names.len();
        let rest = self.pending.len() / plane;
        if self.z + rest != self.dims[2] {
            return Err(Error::InvalidArgument(format!("{}: {} of {} planes pushed", self.path.display(), self.z + rest, self.dims[2])));
        }
        if rest > 0 {
            self.encode_row(rest)?;
        }
        self.scratch.flush().map_err(|e| Error::io(&self.scratch_path, e))?;
        let out_path = part(&self.path, ".part");
        let res = self.assemble(&out_path);
        match res {
            Ok(()) => {
                std::fs::rename(&out_path, &self.path).map_err(|e| Error::io(&self.path, e))?;
                self.done = true;
                Ok(())
            }
            Err(e) => {
                let _ = std::fs::remove_file(&out_path);
                Err(e)
            }
        }
    }

    fn assemble(&self, out_path: &Path) -> Result<()> {
        let io = |e| Error::io(out_path, e);
        let mut out = BufWriter::new(File::create(out_path).map_err(io)?);
        let scratch = File::open(&self.scratch_path).map_err(|e| Error::io(&self.scratch_path, e))?;
        let mut w = file_head(&self.path, self.names.len(), self.xf, &self.options)?;
        let mut base = 0u64;
        let names = unique_names(self.names.iter().map(|s| s.as_str()))?;
        let mut buf = Vec::new();
        for (tree, (unique, name)) in self.trees.iter().zip(names) {
            let (offsets_at, grid_pos) = write_grid_head(&mut w, &unique, name, tree, GridMap::Single(self.xf), &self.options);
            let block_pos = base + w.pos() as u64;
            let end_pos = block_pos + tree.stored().map(|(_, len)| len).sum::<u64>();
            w.patch_i64(offsets_at, (base + grid_pos as u64) as i64);
            w.patch_i64(offsets_at + 8, block_pos as i64);
            w.patch_i64(offsets_at + 16, end_pos as i64);
            out.write_all(&w.buf).map_err(io)?;
            base = block_pos;
            w.buf.clear();
            for (at, len) in tree.stored() {
                buf.resize(len as usize, 0);
                read_exact_at(&scratch, &mut buf, at).map_err(|e| Error::io(&self.scratch_path, e))?;
                out.write_all(&buf).map_err(io)?;
                base += len;
            }
        }
        let file = out.into_inner().map_err(|e| io(e.into_error()))?;
        file.sync_data().map_err(io)
    }
}

impl Drop for PlaneStream {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.scratch_path);
        if !self.done {
            let _ = std::fs::remove_file(part(&self.path, ".part"));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vdb::{write_dense_float_grids, write_rgb_grids, DenseFloat, VdbCompression};

    /// Streamed in uneven batches of planes (1, 3, 8, the rest: rows split across pushes, a
    /// last row of 5 planes), the file equals `write_rgb_grids` of the whole array byte for byte
    /// but for the UUID, uncompressed and Zip, full and half; the scratch file is gone.
    #[test]
    fn streamed_rgb_vdb_equals_the_whole_array_writer() {
        let dims = [13u32, 10, 21];
        let n = (dims[0] * dims[1] * dims[2]) as usize;
        let data: Vec<Vec3> = (0..n)
            .map(|i| {
                let f = i as f32;
                // Zeros in places, so that leaves have inactive voxels and some are empty.
                if (i / 7) % 5 == 0 || i > n - 300 { Vec3::ZERO } else { Vec3::new(f.sin().abs(), (f * 0.3).cos(), f * 1e-3) }
            })
            .collect();
        let xf = Affine3A::from_scale_rotation_translation(Vec3::splat(0.05), glam::Quat::from_rotation_z(0.3), Vec3::new(1.0, -2.0, 0.5));
        let dir = std::env::temp_dir().join(format!("volscatter-stream-vdb-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        for (half, compression) in [(false, VdbCompression::None), (false, VdbCompression::Zip), (true, VdbCompression::Zip)] {
            let o = WriteOptions { half, compression, ..Default::default() };
            let (a, b) = (dir.join("whole.vdb"), dir.join("streamed.vdb"));
            write_rgb_grids(&a, "scattering", dims, &data, xf, &o).unwrap();
            let mut s = RgbVdbStream::create(&b, "scattering", dims, xf, &o).unwrap();
            let plane = (dims[0] * dims[1]) as usize;
            let mut z = 0;
            for k in [1usize, 3, 8, 9] {
                s.push_planes(&data[z * plane..(z + k) * plane]).unwrap();
                z += k;
            }
            assert!(s.push_planes(&data[..plane - 1]).is_err(), "a part of a plane is refused");
            assert!(b.with_extension("vdb.leaves").exists());
            s.finish().unwrap();
            let (x, y) = (std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap());
            assert_eq!(x.len(), y.len(), "half {half} {compression:?}");
            // The UUID: 36 characters after magic (8), versions (3 x 4) and the offsets flag.
            assert!(x[..21] == y[..21] && x[57..] == y[57..], "half {half} {compression:?}");
            assert!(!b.with_extension("vdb.leaves").exists());
            crate::vdb::VdbFile::open(&b, u64::MAX).unwrap();
            // One float grid (the green channel) streamed: `write_dense_float_grids` of it.
            let green: Vec<f32> = data.iter().map(|v| v.y.abs()).collect();
            let (c, d) = (dir.join("float_whole.vdb"), dir.join("float_streamed.vdb"));
            write_dense_float_grids(&c, &[DenseFloat { name: "density", dims, values: &green }], xf, &o).unwrap();
            let mut f = FloatVdbStream::create(&d, "density", dims, xf, &o).unwrap();
            let plane = (dims[0] * dims[1]) as usize;
            f.push_planes(&green[..5 * plane]).unwrap();
            assert!(f.push_planes(&green[..plane + 1]).is_err(), "a part of a plane is refused");
            f.push_planes(&green[5 * plane..]).unwrap();
            f.finish().unwrap();
            let (x, y) = (std::fs::read(&c).unwrap(), std::fs::read(&d).unwrap());
            assert!(x.len() == y.len() && x[..21] == y[..21] && x[57..] == y[57..], "float: half {half} {compression:?}");
        }
        // Unfinished: no output, no scratch file.
        let c = dir.join("unfinished.vdb");
        let mut s = RgbVdbStream::create(&c, "s", dims, xf, &WriteOptions::default()).unwrap();
        s.push_planes(&data[..(dims[0] * dims[1]) as usize]).unwrap();
        let short = RgbVdbStream::create(&dir.join("short.vdb"), "s", dims, xf, &WriteOptions::default()).unwrap();
        assert!(short.finish().unwrap_err().to_string().contains("planes pushed"));
        drop(s);
        assert!(!c.exists() && !c.with_extension("vdb.leaves").exists());
        let _ = std::fs::remove_dir_all(&dir);
    }
}
