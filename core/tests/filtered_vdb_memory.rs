//! Issue 19: a VDB medium read box-filtered (`medium.max_resolution`, vdb/filter.rs) holds at
//! most the coarse grid, the topology and one read window, never the file or the fine voxels:
//! its peak of live bytes, counted by the allocator, against the whole load's.

mod counting_alloc;

use counting_alloc::peak_during;
use volscatter_core::medium::GridLimits;
use volscatter_core::vdb::{load_density, load_density_filtered, write_float_grid, MaxResolution, VdbCompression, WriteOptions};

#[test]
fn filtered_vdb_load_peaks_at_the_coarse_grid_not_the_file() {
    let dir = std::env::temp_dir().join(format!("vs-filtered-memory-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("cumulus.vdb");
    {
        let (grid, xf) = volscatter_core::medium::cumulus::cumulus(192, GridLimits::default()).unwrap();
        write_float_grid(&path, "density", &grid, xf, &WriteOptions { compression: VdbCompression::None, ..Default::default() }).unwrap();
    }
    let size = std::fs::metadata(&path).unwrap().len() as usize;
    let (whole, whole_peak) = peak_during(|| load_density(&path, None, GridLimits::default()).unwrap());
    drop(whole);
    let ((coarse, _, report), peak) = peak_during(|| load_density_filtered(&path, None, MaxResolution::new(16).unwrap(), GridLimits::default()).unwrap());
    // What the filter holds by design (filter.rs): the f64 sums, the f32 means and the grid
    // built from them (its bricks, at most the dense size again, and the builder's table),
    // the two read windows (the tree reader walks the topology again beside the buffers and
    // keeps nothing per leaf); plus 1 MiB for
    // what does not grow with the file (a level-5 internal node's 32^3 values decoded as f64,
    // 256 KiB, and its raw bytes; the header; one leaf; the builder's few bricks).
    let cells = report.accumulator_bytes / 8;
    let bound = report.accumulator_bytes + cells * 4 + 2 * coarse.memory_bytes() + 2 * report.peak_window_bytes as u64 + (1 << 20);
    eprintln!("file {size} B; whole load peak {whole_peak} B; filtered to {:?} (factor {}): peak {peak} B, bound {bound} B ({report:?})", report.coarse_dims, report.factor);
    assert!((peak as u64) <= bound, "peak {peak} over {bound}");
    // The bound is far below what the whole load and the file take: the test can fail.
    assert!(bound * 4 < whole_peak as u64 && bound * 2 < size as u64, "bound {bound}, whole {whole_peak}, file {size}");
    let _ = std::fs::remove_dir_all(&dir);
}
