//! `volscatter render`: scene -> solver -> image (EXR with the AOVs asked for, optional PNG,
//! JSON report).

use clap::Args;
use serde_json::json;
use std::path::PathBuf;
use std::time::Instant;

use super::progress::StderrProgress;
use volscatter_core::pipeline::{self, DeviceUsed};
use volscatter_core::stages::Timings;
use volscatter_core::{compositor, io, Error, Result, Scene};

#[derive(Args)]
pub struct RenderArgs {
    /// Scene JSON (docs/scene-format.md). Without it: the embedded default scene.
    pub scene: Option<PathBuf>,
    /// Solver (`volscatter solvers` lists them): reference (path-traced image) or a scattering
    /// solver composited by ray marching.
    #[arg(long)]
    pub solver: Option<String>,
    #[arg(long, default_value = "out/render.exr")]
    pub out: PathBuf,
    #[arg(long)]
    pub png: Option<PathBuf>,
    /// Also write the solver's scattering grid S as OpenVDB (float grids `scattering_r/_g/_b`
    /// on the grid the solver returns, `output_resolution`), what a host renders as emission.
    /// Not with `reference`, which returns an image.
    #[arg(long = "out-vdb")]
    pub out_vdb: Option<PathBuf>,
    /// Samples per pixel (reference).
    #[arg(long)]
    pub spp: Option<u32>,
    #[arg(long)]
    pub seed: Option<u64>,
    /// Leave the directly seen environment out (alpha from the medium only).
    #[arg(long)]
    pub transparent: bool,
    /// Composite the grid alone, as a host renders it: without the point and spot lamps'
    /// single scattering made exact near them (docs/cli.md).
    #[arg(long)]
    pub grid_only: bool,
    /// Multiplier applied to the PNG only.
    #[arg(long, default_value_t = 1.0)]
    pub exposure: f32,
    /// Write settings, per-phase times and image statistics as JSON.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Solver setting KEY=VALUE (JSON value), repeatable: --set grid_resolution=48.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub settings: Vec<String>,
    /// AOV layers written to the EXR besides RGBA, comma-separated: single, multiple,
    /// background, emission, or all, or none. The default, background, is free (the march computes it for
    /// the image) and is what re-compositing over another backdrop needs; single and multiple
    /// cost the compositor a second light pass (more than pop's solve), so they are asked for.
    #[arg(long = "aov", value_name = "LIST", default_value = "background")]
    pub aovs: String,
    /// Where GPU-capable stages run (pop's propagation, the compositor): gpu, cpu, or auto (a
    /// GPU adapter when one exists, else the CPU with a message).
    #[arg(long, default_value = "auto")]
    pub device: volscatter_gpu::DeviceChoice,
    #[arg(long, short)]
    pub quiet: bool,
}

/// The solver block that applies: the scene's own when it names the chosen solver (or none),
/// then the command-line overrides.
pub fn solver_settings(scene: &Scene, name: &str, args: &RenderArgs) -> Result<serde_json::Map<String, serde_json::Value>> {
    let mut map = match scene.solver_name() {
        None => scene.solver.clone(),
        Some(n) if n == name => scene.solver.clone(),
        Some(_) => Default::default(),
    };
    map.remove("name");
    if let Some(spp) = args.spp {
        map.insert("spp".into(), json!(spp));
    }
    if let Some(seed) = args.seed {
        map.insert("seed".into(), json!(seed));
    }
    for kv in &args.settings {
        let (k, v) = kv
            .split_once('=')
            .ok_or_else(|| Error::InvalidArgument(format!("--set {kv}: expected KEY=VALUE")))?;
        let value = serde_json::from_str(v).unwrap_or_else(|_| json!(v));
        map.insert(k.to_string(), value);
    }
    Ok(map)
}

fn ensure_parent(path: &std::path::Path) -> Result<()> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        // The OS says only "File exists" when a folder on the way is a file: name it.
        if let Some(file) = dir.ancestors().find(|a| !a.as_os_str().is_empty() && a.exists() && !a.is_dir()) {
            return Err(Error::InvalidArgument(format!("{}: {} is a file, not a folder", path.display(), file.display())));
        }
        std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    }
    Ok(())
}

/// Refuses, before anything runs, an output under a file (as if it were a folder) and two
/// outputs naming the same file (one would silently overwrite the other): compared as
/// absolute paths, and as the same existing file.
fn distinct_outputs(outputs: &[(&str, Option<&std::path::Path>)]) -> Result<()> {
    let key = |p: &std::path::Path| std::fs::canonicalize(p).or_else(|_| std::path::absolute(p)).unwrap_or_else(|_| p.to_path_buf());
    for path in outputs.iter().filter_map(|(_, p)| *p) {
        if let Some(file) = path.parent().into_iter().flat_map(|d| d.ancestors()).find(|a| !a.as_os_str().is_empty() && a.exists() && !a.is_dir()) {
            return Err(Error::InvalidArgument(format!("{}: {} is a file, not a folder", path.display(), file.display())));
        }
    }
    let named: Vec<(&str, std::path::PathBuf)> = outputs.iter().filter_map(|(flag, p)| p.map(|p| (*flag, key(p)))).collect();
    for (i, (a, pa)) in named.iter().enumerate() {
        if let Some((b, _)) = named[..i].iter().find(|(_, pb)| pb == pa) {
            return Err(Error::InvalidArgument(format!("{b} and {a} name the same file {}: give each its own", pa.display())));
        }
    }
    Ok(())
}

pub fn run(args: RenderArgs) -> Result<()> {
    distinct_outputs(&[("--out", Some(&args.out)), ("--out-vdb", args.out_vdb.as_deref()), ("--png", args.png.as_deref()), ("--report", args.report.as_deref())])?;
    let start = Instant::now();
    let mut timings = Timings::default();
    let scene = timings.time("load scene", || match &args.scene {
        Some(p) => Scene::load(p),
        None => Ok(Scene::default_scene()),
    })?;
    let name = args.solver.clone().or_else(|| scene.solver_name().map(String::from)).unwrap_or_else(|| "reference".into());
    let settings = solver_settings(&scene, &name, &args)?;
    let aovs = compositor::Aovs::parse(&args.aovs)?;
    // Unknown names and bad settings are refused here, before anything runs.
    let mut session = pipeline::Session::new(&name, &settings, volscatter_gpu::devices(args.device))?;
    if args.out_vdb.is_some() && session.solver().is_some_and(|s| s.name() == "reference") {
        return Err(Error::InvalidArgument("--out-vdb: `reference` renders an image, not a scattering grid; pick a scattering solver".into()));
    }
    let progress = StderrProgress::new(args.quiet);
    let opts = compositor::CompositeOptions { transparent: args.transparent, aovs, near_lamps: !args.grid_only, ..Default::default() };
    let rendered = pipeline::render(&mut session, &scene, &opts, &progress)?;
    progress.finish();
    if !args.quiet {
        for note in &rendered.notes {
            eprintln!("note: {note}");
        }
        if let Some(c) = rendered.solved.as_ref().and_then(|s| s.choice.as_ref()) {
            eprintln!("auto picked {} {}: {}", c.solver, c.quality, c.why);
        }
    }
    timings.0.extend(rendered.timings.0.iter().cloned());
    // A signal after the solve: no output is begun.
    if volscatter_core::Progress::cancelled(&progress) {
        return Err(Error::Cancelled);
    }
    if let (Some(path), Some(solved)) = (&args.out_vdb, &rendered.solved) {
        ensure_parent(path)?;
        let s = &solved.output.scattering;
        timings.time("write S (VDB)", || volscatter_core::vdb::write_rgb_grids(path, "scattering", s.dims, &s.data, s.index_to_world, &Default::default()))?;
    }
    let image = rendered.image;
    let solve_device = rendered.solved.as_ref().map(|s| s.device.clone()).unwrap_or(DeviceUsed::Cpu);
    let device_used = rendered.device;
    let counters = rendered.solved.as_ref().map(|s| s.output.counters.clone());
    let choice = rendered.solved.and_then(|s| s.choice);
    ensure_parent(&args.out)?;
    timings.time("write", || -> Result<()> {
        io::exr::write_image(&args.out, &image)?;
        if let Some(png) = &args.png {
            ensure_parent(png)?;
            io::png::write_png(png, &image, args.exposure, args.transparent)?;
        }
        Ok(())
    })?;
    let stats = image.stats();
    if !args.quiet {
        eprintln!(
            "{}: {}x{} with `{name}` in {:.2} s, mean RGB ({:.4}, {:.4}, {:.4}), mean alpha {:.3}",
            args.out.display(),
            image.width,
            image.height,
            start.elapsed().as_secs_f64(),
            stats.mean_rgb[0],
            stats.mean_rgb[1],
            stats.mean_rgb[2],
            stats.mean_alpha
        );
    }
    if let Some(report) = &args.report {
        // A phase that runs once per light (pop's grids) is reported as its total.
        let mut phases = serde_json::Map::new();
        for (k, v) in &timings.0 {
            let total = phases.get(k).and_then(|x| x.as_f64()).unwrap_or(0.0) + v;
            phases.insert(k.clone(), json!(total));
        }
        let mut doc = json!({
            "scene": args.scene.as_ref().map(|p| p.display().to_string()),
            "solver": name,
            "device": {"solve": solve_device.to_string(), "composite": device_used.to_string()},
            "settings": settings,
            "width": image.width,
            "height": image.height,
            "threads": rayon_threads(),
            "phases_seconds": phases,
            "total_seconds": start.elapsed().as_secs_f64(),
            "image": stats,
        });
        // What the solve computed and kept, and on a device what it created and moved.
        if let Some(c) = &counters {
            doc["counters"] = serde_json::to_value(c).unwrap_or(serde_json::Value::Null);
        }
        // What `auto` picked and why (solver, quality, settings, predictions, the sentence).
        if let Some(c) = &choice {
            doc["auto"] = serde_json::to_value(c).unwrap_or(serde_json::Value::Null);
        }
        ensure_parent(report)?;
        volscatter_core::io::files::write_file_atomic(report, serde_json::to_string_pretty(&doc).unwrap().as_bytes())?;
    }
    Ok(())
}

fn rayon_threads() -> usize {
    std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1)
}
