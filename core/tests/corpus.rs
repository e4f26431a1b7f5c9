//! Every file of tests/corpus (issue 22's reproducers and what the fuzz harnesses found) is read
//! by the part of the library it targets; each must give OK or a clean error: no panic, and a
//! message that quotes at most an excerpt of the input. `write_corpus` (ignored) regenerates the
//! VDB and JSON files; the EXR ones come from tests/hostile_exr.rs.

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};

use volscatter_core::medium::GridLimits;
use volscatter_core::vdb::VdbFile;
use volscatter_core::{Error, Result, Scene};

fn corpus() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/corpus")
}

fn files(kind: &str) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(corpus().join(kind)).unwrap().map(|e| e.unwrap().path()).filter(|p| p.is_file()).collect();
    v.sort();
    v
}

/// What a host does with each kind of file.
fn read(kind: &str, path: &Path) -> Result<()> {
    match kind {
        "json" => Scene::load(path).map(|_| ()),
        "exr" => volscatter_core::io::exr::read_latlong(path).map(|_| ()),
        "vdb" => {
            let f = VdbFile::open(path, 64 << 20)?;
            for i in 0..f.grids.len() {
                f.grid_info(i)?;
            }
            let i = f.find_density_grid(None)?;
            f.load_float_grid(i, GridLimits::default()).map(|_| ())
        }
        _ => unreachable!(),
    }
}

/// Longest message accepted: a 200-character excerpt, a path and a fixed frame of words.
const MAX_MESSAGE: usize = 1200;

#[test]
fn every_corpus_file_is_ok_or_a_clean_error() {
    // The budget a host under `ulimit -v 4 GB` gets by default (half of it).
    volscatter_core::budget::set_budget(Some(2 << 30));
    let mut seen = 0;
    for kind in ["json", "exr", "vdb"] {
        for path in files(kind) {
            let res = catch_unwind(AssertUnwindSafe(|| read(kind, &path)));
            match res {
                Err(_) => panic!("{}: panicked", path.display()),
                Ok(Ok(())) => eprintln!("{}: OK", path.display()),
                Ok(Err(e)) => {
                    let m = e.to_string();
                    assert!(m.len() <= MAX_MESSAGE, "{}: message of {} bytes: {}", path.display(), m.len(), &m[..300]);
                    eprintln!("{}: {m}", path.display());
                }
            }
            seen += 1;
        }
    }
    assert!(seen >= 8, "corpus has only {seen} files");
}

/// The corpus cases that must be refused, with a word of the refusal each (the others may load).
#[test]
fn corpus_refusals_say_why() {
    volscatter_core::budget::set_budget(Some(1 << 30));
    let expect = [
        ("json/trailing_text.json", "text after the scene's JSON object"),
        ("json/rgb_as_string.json", "[r, g, b]"),
        ("json/huge_grid_name.json", "no grid named"),
        ("json/huge_procedural_name.json", "unknown procedural medium"),
        ("json/huge_unknown_key.json", "unknown field"),
        ("json/dome_single_huge_tile.json", "EXR block"),
        ("json/dome_header_only.json", "exr"),
    ];
    for (file, word) in expect {
        let path = corpus().join(file);
        let kind = file.split('/').next().unwrap();
        let e: Error = read(kind, &path).expect_err(file);
        let m = e.to_string();
        assert!(m.contains(word) && m.len() <= MAX_MESSAGE, "{file}: {}", &m[..m.len().min(400)]);
    }
}

/// Regenerates tests/corpus/{json,vdb} (`--run-ignored only`); the files are committed.
#[test]
#[ignore]
fn write_corpus() {
    use volscatter_core::vdb::writer::{write_dense_float_grids, DenseFloat, WriteOptions};
    let json = corpus().join("json");
    let vdb = corpus().join("vdb");
    let values: Vec<f32> = (0..64).map(|i| (i % 7) as f32 / 7.0).collect();
    let dense = |name| DenseFloat { name, dims: [4, 4, 4], values: &values };
    let xf = glam::Affine3A::from_scale(glam::Vec3::splat(0.1));
    write_dense_float_grids(&vdb.join("tiny_density.vdb"), &[dense("density")], xf, &WriteOptions::default()).unwrap();
    // A 20 KB grid name (100 times the quote limit): its messages must quote an excerpt.
    let long = "n".repeat(20_000);
    write_dense_float_grids(&vdb.join("huge_grid_name.vdb"), &[dense(&long)], xf, &WriteOptions::default()).unwrap();
    let base = volscatter_core::scene::DEFAULT_SCENE_JSON.replace(r#""width": 256, "height": 256"#, r#""width": 32, "height": 32"#);
    let vdb_medium = r#""vdb": "../vdb/tiny_density.vdb""#;
    let with_medium = |m: &str| base.replace(r#""procedural": "plume", "dims": [64]"#, m);
    let with_dome = |tex: &str| base.replace(r#""color": [0.12, 0.17, 0.28]"#, &format!(r#""texture": "../exr/{tex}""#));
    let huge = "x".repeat(20_000);
    let cases = [
        ("trailing_text.json", format!("{base}\n{{\"format\": 1}}\n")),
        ("rgb_as_string.json", base.replace("[5.0, 4.6, 4.0]", r#""bright""#)),
        ("huge_grid_name.json", with_medium(&format!(r#"{vdb_medium}, "grid": "{huge}""#))),
        ("huge_procedural_name.json", with_medium(&format!(r#""procedural": "{huge}""#))),
        ("huge_unknown_key.json", base.replace(r#""camera": {"#, &format!(r#""{huge}": 1, "camera": {{"#))),
        ("dome_single_huge_tile.json", with_dome("single_tile_16384x8192.exr")),
        ("dome_header_only.json", with_dome("header_16384x8192_scanlines.exr")),
        ("vdb_tiny.json", with_medium(vdb_medium)),
    ];
    for (name, text) in cases {
        std::fs::write(json.join(name), text).unwrap();
    }
}
