//! Fuzz harnesses that run on stable Rust (issue 22): proptest drives seeded mutations of valid
//! inputs (the corpus files and small files made here) through the VDB reader, the EXR dome
//! loader and the scene JSON parser. Each case must end in OK or an error, never a panic, and
//! errors must stay short. CI runs a fixed seed and a bounded number of cases (about 10 s in
//! all on one core); `VOLSCATTER_FUZZ_CASES=N` runs a longer campaign, and a failing input is
//! printed minimised by proptest: add it to tests/corpus.

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};

use proptest::prelude::*;
use proptest::test_runner::{Config, RngAlgorithm, TestRng, TestRunner};

use volscatter_core::medium::GridLimits;
use volscatter_core::vdb::VdbFile;
use volscatter_core::Scene;

fn corpus() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/corpus")
}

fn runner(default_cases: u32, seed: u8) -> TestRunner {
    let cases = std::env::var("VOLSCATTER_FUZZ_CASES").ok().and_then(|v| v.parse().ok()).unwrap_or(default_cases);
    let config = Config { cases, failure_persistence: None, ..Config::default() };
    TestRunner::new_with_rng(config, TestRng::from_seed(RngAlgorithm::ChaCha, &[seed; 32]))
}

/// One edit of a byte string: overwrite, flip a bit, insert, delete, or set a 4/8-byte field to
/// a large value (the sizes and counts of binary formats).
#[derive(Clone, Debug)]
enum Edit {
    Set(usize, u8),
    Flip(usize, u8),
    Insert(usize, Vec<u8>),
    Delete(usize, usize),
    Large(usize, bool),
}

fn edits() -> impl Strategy<Value = Vec<Edit>> {
    let edit = prop_oneof![
        (any::<usize>(), any::<u8>()).prop_map(|(i, b)| Edit::Set(i, b)),
        (any::<usize>(), 0u8..8).prop_map(|(i, b)| Edit::Flip(i, b)),
        (any::<usize>(), proptest::collection::vec(any::<u8>(), 1..16)).prop_map(|(i, v)| Edit::Insert(i, v)),
        (any::<usize>(), 1usize..64).prop_map(|(i, n)| Edit::Delete(i, n)),
        (any::<usize>(), any::<bool>()).prop_map(|(i, wide)| Edit::Large(i, wide)),
    ];
    proptest::collection::vec(edit, 1..6)
}

/// Applies `edits`; `head` > 0 aims them at the first `head` bytes (headers, where sizes live).
fn mutate(mut data: Vec<u8>, edits: &[Edit], head: usize) -> Vec<u8> {
    for e in edits {
        let span = if head > 0 { data.len().min(head) } else { data.len() }.max(1);
        match e {
            Edit::Set(i, b) if !data.is_empty() => data[i % span] = *b,
            Edit::Flip(i, b) if !data.is_empty() => data[i % span] ^= 1 << b,
            Edit::Insert(i, v) => {
                let at = (i % span).min(data.len());
                data.splice(at..at, v.iter().copied());
            }
            Edit::Delete(i, n) if !data.is_empty() => {
                let at = i % span.min(data.len());
                let end = (at + n).min(data.len());
                data.drain(at..end);
            }
            Edit::Large(i, wide) if !data.is_empty() => {
                let v: &[u8] = if *wide { &[0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0x7f] } else { &[0xff, 0xff, 0xff, 0x7f] };
                let at = i % span;
                let m = (data.len() - at).min(v.len());
                data[at..at + m].copy_from_slice(&v[..m]);
            }
            _ => {}
        }
    }
    data
}

/// Errors quote at most an excerpt of the input.
const MAX_MESSAGE: usize = 1200;

fn clean<T>(what: &str, f: impl FnOnce() -> volscatter_core::Result<T>) -> Result<(), TestCaseError> {
    match catch_unwind(AssertUnwindSafe(f)) {
        Err(_) => Err(TestCaseError::fail(format!("{what}: panicked"))),
        Ok(Err(e)) if e.to_string().len() > MAX_MESSAGE => Err(TestCaseError::fail(format!("{what}: message of {} bytes", e.to_string().len()))),
        Ok(_) => Ok(()),
    }
}

fn seeds(kind: &str, ext: &str) -> Vec<Vec<u8>> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(corpus().join(kind)).unwrap().map(|e| e.unwrap().path()).collect();
    v.retain(|p| p.extension().is_some_and(|e| e == ext) && std::fs::metadata(p).unwrap().len() < 64 << 10);
    v.sort();
    v.iter().map(|p| std::fs::read(p).unwrap()).collect()
}

#[test]
fn vdb_reader_survives_mutations() {
    let seeds = seeds("vdb", "vdb");
    assert!(!seeds.is_empty());
    let limits = GridLimits { max_bytes: 64 << 20, max_extent_voxels: 1 << 27 };
    let strategy = (0..seeds.len(), edits(), prop_oneof![Just(0usize), Just(1024usize)]);
    runner(300, 1)
        .run(&strategy, |(s, e, head)| {
            let data = mutate(seeds[s].clone(), &e, head);
            clean("vdb", || {
                let f = VdbFile::from_bytes(data, Path::new("fuzz.vdb"))?;
                for i in 0..f.grids.len() {
                    let _ = f.grid_info(i);
                    let _ = f.load_float_grid(i, limits);
                }
                Ok(())
            })
        })
        .unwrap();
}

#[test]
fn exr_dome_loader_survives_mutations() {
    let dir = std::env::temp_dir().join(format!("vs-fuzz-exr-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    // A small valid map (ZIP scanlines, RGBA f32, an AOV) beside the corpus's hostile headers.
    let valid = dir.join("valid.exr");
    let mut img = volscatter_core::Image::new(8, 4);
    img.rgba.iter_mut().enumerate().for_each(|(i, p)| *p = glam::Vec4::new(i as f32, 1.0, 2.0, 1.0));
    img.aovs.push(("single".into(), vec![glam::Vec3::ONE; 32]));
    volscatter_core::io::exr::write_image(&valid, &img).unwrap();
    let mut seeds = seeds("exr", "exr");
    seeds.push(std::fs::read(&valid).unwrap());
    // 1 GiB: the hostile headers must be refused by the budget, not decoded.
    volscatter_core::budget::set_budget(Some(1 << 30));
    let path = dir.join("case.exr");
    let strategy = (0..seeds.len(), edits(), prop_oneof![Just(0usize), Just(400usize)]);
    runner(300, 2)
        .run(&strategy, |(s, e, head)| {
            std::fs::write(&path, mutate(seeds[s].clone(), &e, head)).unwrap();
            clean("exr", || volscatter_core::io::exr::read_latlong(&path).map(|_| ()))
        })
        .unwrap();
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn scene_json_survives_mutations() {
    // Text mutations of small scenes (the default one, which builds a 64^3 plume, is replaced by
    // an 8^3 one so that each accepted case is cheap).
    let mut seeds: Vec<Vec<u8>> = vec![volscatter_core::scene::DEFAULT_SCENE_JSON.replace("[64]", "[8]").into_bytes()];
    seeds.extend(seeds_small_json());
    let base = corpus().join("json");
    let strategy = (0..seeds.len(), edits(), any::<bool>());
    runner(400, 3)
        .run(&strategy, |(s, e, structural)| {
            let bytes = mutate(seeds[s].clone(), &e, 0);
            let mut text = String::from_utf8_lossy(&bytes).into_owned();
            if structural {
                // Numbers made extreme, the other way JSON goes wrong.
                text = text.replacen("0.6", "1e39", 1).replacen("256", "4294967295", 1);
            }
            // Dims stay small: the procedural grid's size is the compute side's budget check.
            if text.contains("dims") && !text.contains("[8]") {
                return Ok(());
            }
            clean("json", || Scene::from_json_str(&text, &base).map(|_| ()))
        })
        .unwrap();
}

/// The corpus scenes under 4 KB that do not name a dome texture (those are exercised by the EXR
/// harness).
fn seeds_small_json() -> Vec<Vec<u8>> {
    seeds("json", "json").into_iter().filter(|s| s.len() < 4096 && !String::from_utf8_lossy(s).contains("texture")).collect()
}
