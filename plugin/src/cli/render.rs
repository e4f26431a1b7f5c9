//! `volscatter render`: scene -> solver -> image (EXR with the AOVs asked for, optional PNG,
//! JSON report).

use clap::Args;
use serde_json::json;
use std::path::PathBuf;
use std::time::Instant;

use super::progress::StderrProgress;
use volscatter_core::solvers::{reference::Reference, registry};
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
    /// background, or all, or none. The default, background, is free (the march computes it for
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
    if args.transparent && name == "reference" {
        map.insert("transparent".into(), json!(true));
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
        std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    }
    Ok(())
}

pub fn run(args: RenderArgs) -> Result<()> {
    let start = Instant::now();
    let mut timings = Timings::default();
    let scene = timings.time("load scene", || match &args.scene {
        Some(p) => Scene::load(p),
        None => Ok(Scene::default_scene()),
    })?;
    let name = args.solver.clone().or_else(|| scene.solver_name().map(String::from)).unwrap_or_else(|| "reference".into());
    // Unknown names are refused before anything runs, with the registry's list.
    registry::get(&name)?;
    let settings = solver_settings(&scene, &name, &args)?;
    let aovs = compositor::Aovs::parse(&args.aovs)?;
    let progress = StderrProgress::new(args.quiet);
    let mut device_used = volscatter_gpu::DeviceUsed::Cpu;
    let mut solve_device = volscatter_gpu::DeviceUsed::Cpu;
    let mut choice = None;
    if name == "reference" && args.out_vdb.is_some() {
        return Err(Error::InvalidArgument("--out-vdb: `reference` renders an image, not a scattering grid; pick a scattering solver".into()));
    }
    let image = if name == "reference" {
        let r = Reference::from_settings(&settings)?;
        let mut img = r.render_image(&scene, &progress, &mut timings)?;
        progress.finish();
        // The path tracer's layers cost nothing extra; the EXR still holds only those asked
        // for, so that its layers do not depend on the solver.
        img.aovs.retain(|(layer, _)| aovs.contains(layer));
        img
    } else {
        let (out, solved_on) = volscatter_gpu::solve(args.device, &scene, &name, &settings, &progress)?;
        solve_device = solved_on;
        progress.finish();
        if let (Some(c), false) = (&out.choice, args.quiet) {
            eprintln!("auto picked {} {}: {}", c.solver, c.quality, c.why);
        }
        choice = out.choice;
        timings.0.extend(out.timings.0);
        if let Some(path) = &args.out_vdb {
            ensure_parent(path)?;
            let s = &out.scattering;
            timings.time("write S (VDB)", || volscatter_core::vdb::write_rgb_grids(path, "scattering", s.dims, &s.data, s.index_to_world, &Default::default()))?;
        }
        let opts = compositor::CompositeOptions { transparent: args.transparent, aovs, ..Default::default() };
        // Timed apart from the march (phase "composite: single-scattering AOV", included in
        // "composite", present only when an AOV needs it): the part an image without those
        // AOVs skips.
        let start_composite = Instant::now();
        let single = if opts.aovs.needs_single() {
            let (single, _) = timings
                .time("composite: single-scattering AOV", || {
                    volscatter_gpu::run_on(
                        args.device,
                        |ctx| volscatter_gpu::composite::single_for(ctx, &scene, &opts).map(Ok),
                        || compositor::single_for(&scene, &opts),
                    )
                })
                .map_err(Error::from)?;
            single?
        } else {
            None
        };
        let (img, used_march) = volscatter_gpu::run_on(
            args.device,
            |ctx| volscatter_gpu::composite::composite_with_single(ctx, &scene, &out.scattering, single.as_ref(), &opts).map(Ok),
            || compositor::composite_with_single(&scene, &out.scattering, single.as_ref(), &opts),
        )
        .map_err(Error::from)?;
        timings.0.push(("composite".into(), start_composite.elapsed().as_secs_f64()));
        // Both stages ask for the same device; under auto a fall-back is noted on stderr.
        device_used = used_march;
        img?
    };
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
        // What `auto` picked and why (solver, quality, settings, predictions, the sentence).
        if let Some(c) = &choice {
            doc["auto"] = serde_json::to_value(c).unwrap_or(serde_json::Value::Null);
        }
        ensure_parent(report)?;
        volscatter_core::io::files::write_file(report, serde_json::to_string_pretty(&doc).unwrap().as_bytes())?;
    }
    Ok(())
}

fn rayon_threads() -> usize {
    std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1)
}
