//! `volscatter compare SCENE --solvers pop,reference`: renders the scene with each solver
//! (`reference`: path-traced image; others: solve, then the compositor), and reports the
//! relative RMSE of each image and scattering grid against the baseline (`reference` when it
//! is listed, else the last solver), with the time each took. `--json FILE` writes the same.
//! Solver names and settings come from the registry; `--device` says where GPU-capable solvers
//! and the compositor run (default cpu, so that benchmark times stay those of the CPU path).

use clap::Args;
use serde_json::json;
use std::path::PathBuf;
use std::time::Instant;

use super::progress::StderrProgress;
use volscatter_core::compositor::CompositeOptions;
use volscatter_core::image::relative_rmse;
use volscatter_core::pipeline::{self, DeviceUsed};
use volscatter_core::solvers::registry;
use volscatter_core::stages::{ScatteringGrid, Timings};
use volscatter_core::{Error, Image, Result, Scene};

#[derive(Args)]
pub struct CompareArgs {
    /// Scene JSON. Without it: the embedded default scene.
    pub scene: Option<PathBuf>,
    /// Comma-separated solver names; the baseline is `reference` if listed, else the last.
    /// `reference@N` is the reference at N paths per pixel with its own seed (for error versus
    /// time curves against a converged baseline); it gets no scattering grid. `NAME#LABEL` is
    /// NAME once more with the settings `--set NAME#LABEL.KEY=VALUE` on top of `--set NAME.KEY`
    /// (several variants of one solver against one baseline).
    #[arg(long, default_value = "pop,reference")]
    pub solvers: String,
    /// Setting for one solver, SOLVER.KEY=VALUE (JSON value), repeatable:
    /// --set pop.grid_resolution=16 --set reference.spp=256.
    #[arg(long = "set", value_name = "SOLVER.KEY=VALUE")]
    pub settings: Vec<String>,
    /// Override the camera's image size.
    #[arg(long)]
    pub width: Option<u32>,
    #[arg(long)]
    pub height: Option<u32>,
    /// Resolution (largest side) of the grid on which scattering grids are compared; the
    /// reference estimates S there with `--grid-spp` paths per point.
    #[arg(long, default_value_t = 32)]
    pub grid_resolution: u32,
    #[arg(long, default_value_t = 256)]
    pub grid_spp: u32,
    /// Skip the scattering-grid comparison (it costs a reference grid estimate).
    #[arg(long)]
    pub no_grid: bool,
    /// Write the results as JSON.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Write each image as EXR into this directory (SOLVER.exr).
    #[arg(long)]
    pub out_dir: Option<PathBuf>,
    /// Where solvers with a GPU backend and the compositor run: cpu (default), gpu, or auto (a
    /// hardware GPU when one works, else the CPU). The reference always runs on the CPU.
    #[arg(long, default_value = "cpu")]
    pub device: volscatter_gpu::DeviceChoice,
    #[arg(long, short)]
    pub quiet: bool,
}

struct Run {
    name: String,
    image: Image,
    grid: Option<ScatteringGrid>,
    image_seconds: f64,
    grid_seconds: f64,
    phases: Timings,
    settings: serde_json::Map<String, serde_json::Value>,
    device: String,
}

fn settings_for(scene: &Scene, name: &str, args: &CompareArgs) -> Result<serde_json::Map<String, serde_json::Value>> {
    let mut map = match scene.solver_name() {
        Some(n) if n == name => scene.solver.clone(),
        _ => Default::default(),
    };
    map.remove("name");
    for kv in &args.settings {
        let (k, v) = kv.split_once('=').ok_or_else(|| Error::InvalidArgument(format!("--set {kv}: expected SOLVER.KEY=VALUE")))?;
        let (solver, key) = k
            .split_once('.')
            .ok_or_else(|| Error::InvalidArgument(format!("--set {kv}: name the solver, as in pop.{k}=...")))?;
        registry::get(solver.split('#').next().unwrap_or("")).map_err(|e| Error::InvalidArgument(format!("--set {kv}: {e}")))?;
        if solver == name {
            map.insert(key.to_string(), serde_json::from_str(v).unwrap_or_else(|_| json!(v)));
        }
    }
    Ok(map)
}

/// Resamples `g` (trilinear) at the points of `frame`.
fn resample(g: &ScatteringGrid, frame: &ScatteringGrid) -> Vec<glam::Vec3> {
    let to_g = g.index_to_world.inverse();
    let [nx, ny, nz] = frame.dims;
    let mut out = Vec::with_capacity(frame.len());
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                out.push(g.sample_index(to_g.transform_point3(frame.position(i, j, k))));
            }
        }
    }
    out
}

fn scattered(img: &Image) -> Vec<glam::Vec3> {
    let bg = img.aov("background");
    img.rgba.iter().enumerate().map(|(i, p)| p.truncate() - bg.map(|b| b[i]).unwrap_or_default()).collect()
}

pub fn run(args: CompareArgs) -> Result<()> {
    let mut scene = match &args.scene {
        Some(p) => Scene::load(p)?,
        None => Scene::default_scene(),
    };
    if args.width.is_some() || args.height.is_some() {
        let c = &scene.camera;
        let (w, h) = (args.width.unwrap_or(c.width), args.height.unwrap_or(c.height));
        if w == 0 || h == 0 || w > 16384 || h > 16384 {
            return Err(Error::InvalidArgument(format!("image size {w}x{h} out of range")));
        }
        scene.camera.width = w;
        scene.camera.height = h;
    }
    let names: Vec<String> = args.solvers.split(',').map(|s| s.trim().to_string()).filter(|s| !s.is_empty()).collect();
    if names.len() < 2 {
        return Err(Error::InvalidArgument("--solvers needs at least two names".into()));
    }
    for n in &names {
        let base_name = n.split(['@', '#']).next().unwrap_or("");
        if let Some(spp) = n.strip_prefix("reference@") {
            if spp.parse::<u32>().map_or(true, |v| v == 0) {
                return Err(Error::InvalidArgument(format!("`{n}`: expected reference@SPP with SPP > 0")));
            }
        } else if n.contains('@') || (n.contains('#') && base_name == "reference") {
            return Err(Error::InvalidArgument(format!("`{n}`: only reference@SPP and NAME#LABEL (NAME not reference) are variants")));
        } else {
            registry::get(base_name)?;
        }
    }
    // The frame every scattering grid is compared on.
    let frame = ScatteringGrid::over_medium(&scene.medium, args.grid_resolution)?;
    let progress = StderrProgress::new(args.quiet);
    let mut runs = Vec::new();
    for (index, name) in names.iter().enumerate() {
        let sweep_spp = name.strip_prefix("reference@").and_then(|v| v.parse::<u32>().ok());
        let solver_name = if sweep_spp.is_some() { "reference" } else { name.split('#').next().unwrap_or("") };
        let mut settings = settings_for(&scene, solver_name, &args)?;
        if name.contains('#') {
            settings.extend(settings_for(&scene, name, &args)?);
        }
        if let Some(spp) = sweep_spp {
            settings.insert("spp".into(), json!(spp));
            settings.insert("seed".into(), json!(1000 + index as u64));
        }
        // Every run through the pipeline: the reference renders its image, the others solve and
        // composite (CompositeOptions::default: every AOV, as the reference's image has).
        let devices = volscatter_gpu::devices(args.device);
        let mut session = pipeline::Session::new(solver_name, &settings, devices)?;
        let t = Instant::now();
        let rendered = pipeline::render(&mut session, &scene, &CompositeOptions::default(), &progress)?;
        let image_seconds = t.elapsed().as_secs_f64();
        if !args.quiet {
            // The library never prints: what it has to say (a fall-back to the CPU, a light left out).
            for note in &rendered.notes {
                eprintln!("note: {name}: {note}");
            }
        }
        let mut phases = rendered.timings;
        let composite_seconds: f64 = phases.0.iter().filter(|(k, _)| k == "composite").map(|(_, v)| v).sum();
        let device = rendered.solved.as_ref().map(|s| s.device.clone()).unwrap_or(DeviceUsed::Cpu);
        let image = rendered.image;
        let (grid, grid_seconds) = match rendered.solved {
            Some(solved) => (Some(solved.output.scattering), image_seconds - composite_seconds),
            // The reference's S, as a point estimate on the comparison grid (output_resolution 0).
            None if name == "reference" && !args.no_grid => {
                let mut gs = settings.clone();
                gs.insert("grid_resolution".into(), json!(args.grid_resolution));
                gs.insert("grid_spp".into(), json!(args.grid_spp));
                gs.insert("output_resolution".into(), json!(0));
                let t = Instant::now();
                let solved = pipeline::solve(&scene, "reference", &gs, devices, &progress)?;
                phases.0.extend(solved.output.timings.0);
                (Some(solved.output.scattering), t.elapsed().as_secs_f64())
            }
            None => (None, 0.0),
        };
        progress.finish();
        if let Some(dir) = &args.out_dir {
            std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
            volscatter_core::io::exr::write_image(&dir.join(format!("{name}.exr")), &image)?;
        }
        runs.push(Run { name: name.clone(), image, grid, image_seconds, grid_seconds, phases, settings, device: device.to_string() });
    }
    let base = names.iter().position(|n| n == "reference").unwrap_or(names.len() - 1);
    let base_rgb: Vec<glam::Vec3> = runs[base].image.rgba.iter().map(|p| p.truncate()).collect();
    let base_scat = scattered(&runs[base].image);
    let base_grid = runs[base].grid.as_ref().map(|g| resample(g, &frame));
    let mut rows = Vec::new();
    println!("baseline: {}   image {}x{}", runs[base].name, scene.camera.width, scene.camera.height);
    println!("{:<12} {:>12} {:>14} {:>12} {:>10} {:>10}", "solver", "image rRMSE", "scatter rRMSE", "grid rRMSE", "image s", "grid s");
    for r in &runs {
        let rgb: Vec<glam::Vec3> = r.image.rgba.iter().map(|p| p.truncate()).collect();
        let img_err = relative_rmse(&rgb, &base_rgb);
        let scat_err = relative_rmse(&scattered(&r.image), &base_scat);
        let resampled = r.grid.as_ref().map(|g| resample(g, &frame));
        let grid_err = match (&resampled, &base_grid) {
            (Some(g), Some(b)) => Some(relative_rmse(g, b)),
            _ => None,
        };
        // Mean of S over the comparison frame (RGB), to tell bias from noise.
        let grid_mean = resampled.as_ref().map(|g| (g.iter().copied().sum::<glam::Vec3>() / g.len().max(1) as f32).to_array());
        println!(
            "{:<12} {:>12.4} {:>14.4} {:>12} {:>10.3} {:>10.3}",
            r.name,
            img_err,
            scat_err,
            grid_err.map(|e| format!("{e:.4}")).unwrap_or_else(|| "-".into()),
            r.image_seconds,
            r.grid_seconds
        );
        let phases: serde_json::Map<String, serde_json::Value> = r.phases.0.iter().map(|(k, v)| (k.clone(), json!(v))).collect();
        rows.push(json!({
            "solver": r.name,
            "settings": r.settings,
            "device": r.device,
            "image_relative_rmse": img_err,
            "scattered_relative_rmse": scat_err,
            "grid_relative_rmse": grid_err,
            "grid_mean": grid_mean,
            "image_seconds": r.image_seconds,
            "grid_seconds": r.grid_seconds,
            "phases_seconds": phases,
            "image": r.image.stats(),
        }));
    }
    if let Some(path) = &args.json {
        let doc = json!({
            "scene": args.scene.as_ref().map(|p| p.display().to_string()),
            "baseline": runs[base].name,
            "width": scene.camera.width,
            "height": scene.camera.height,
            "grid_dims": frame.dims,
            "grid_spp": args.grid_spp,
            "threads": std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1),
            "runs": rows,
        });
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
        }
        volscatter_core::io::files::write_file_atomic(path, serde_json::to_string_pretty(&doc).unwrap().as_bytes())?;
    }
    Ok(())
}
