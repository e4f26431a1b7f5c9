//! The one path from a scene to a result: guard -> auto -> device -> solve -> composite. The
//! CLI (`render`, `compare`), the C ABI (one-off solves and sessions) and every host call these
//! functions and nothing below them, so that each step is decided in one place.
//!
//! - `Session::solve`: the scattering grid (a one-off solve is a session of one frame).
//! - `composite`: a scattering grid ray-marched into the camera's image, on the devices asked for.
//! - `render`: the image, by solve + composite, or by a solver that renders images itself (the
//!   reference path tracer).

pub mod auto;
pub mod device;
pub mod guard;
pub mod session;
#[cfg(test)]
mod session_tests;

use std::time::Instant;

use serde_json::{Map, Value};

use crate::compositor::{self, CompositeOptions};
use crate::error::Result;
use crate::image::Image;
use crate::scene::Scene;
use crate::stages::{Progress, ScatteringGrid, Timings};
pub use device::{Accelerator, Attempt, DeviceChoice, DeviceUsed, Devices};
use session::Frame;
pub use session::{Session, Solved};

/// A one-off solve of `scene` with solver `name` and `settings`.
pub fn solve(scene: &Scene, name: &str, settings: &Map<String, Value>, devices: Devices, progress: &dyn Progress) -> Result<Solved> {
    Session::new(name, settings, devices)?.solve(scene, progress)
}

/// A composited image and where it ran.
pub struct Composited {
    pub image: Image,
    pub device: DeviceUsed,
    pub notes: Vec<String>,
    /// "composite: single-scattering AOV" (when an AOV needs it), "composite: near lamps" (when
    /// asked for) and "composite" (all of it).
    pub timings: Timings,
}

/// Ray-marches `s` into the camera's image with the AOVs `opts` asks for: the single-scattering
/// grid first when an AOV needs it, then the march, both on the devices asked for.
pub fn composite(scene: &Scene, s: &ScatteringGrid, opts: &CompositeOptions, devices: Devices) -> Result<Composited> {
    let mut notes = Vec::new();
    let mut timings = Timings::default();
    let start = Instant::now();
    let single = if opts.aovs.needs_single() {
        let (single, _) = timings.time("composite: single-scattering AOV", || {
            devices.run(&mut notes, true, |on| match on {
                Some((accelerator, choice)) => accelerator.single_for(choice, scene, opts),
                None => compositor::single_for(scene, opts).map(|s| Attempt::Ran(s, DeviceUsed::Cpu)),
            })
        })?;
        single
    } else {
        None
    };
    let (mut image, device) = devices.run(&mut notes, true, |on| match on {
        Some((accelerator, choice)) => accelerator.composite(choice, scene, s, single.as_ref(), opts),
        None => compositor::composite_with_single(scene, s, single.as_ref(), opts).map(|i| Attempt::Ran(i, DeviceUsed::Cpu)),
    })?;
    if opts.near_lamps {
        timings.time("composite: near lamps", || compositor::add_near_lamps(scene, s, single.as_ref(), opts, &mut image));
    }
    timings.0.push(("composite".into(), start.elapsed().as_secs_f64()));
    Ok(Composited { image, device, notes, timings })
}

/// An image and how it was made.
pub struct Rendered {
    pub image: Image,
    /// The solve behind the image; None when the solver rendered the image itself.
    pub solved: Option<Solved>,
    /// Where the composite ran (the solve's device is in `solved`).
    pub device: DeviceUsed,
    pub notes: Vec<String>,
    /// Every step's time, in order: the solve's stages, then the composite's.
    pub timings: Timings,
}

/// The camera's image of `scene`: a solver that renders images itself (the path tracer) renders
/// it, any other solves and the result is composited. The image holds the AOVs `opts` asks for.
pub fn render(session: &mut Session, scene: &Scene, opts: &CompositeOptions, progress: &dyn Progress) -> Result<Rendered> {
    let solved = match session.render_frame(scene, progress, opts.transparent)? {
        Frame::Image { mut image, timings, notes } => {
            // The path tracer's layers cost nothing extra; the image still holds only those
            // asked for, so that its layers do not depend on the solver.
            image.aovs.retain(|(layer, _)| opts.aovs.contains(layer));
            return Ok(Rendered { image, solved: None, device: DeviceUsed::Cpu, notes, timings });
        }
        Frame::Solved(solved) => solved,
    };
    let composited = composite(scene, &solved.output.scattering, opts, session.devices())?;
    let mut timings = solved.output.timings.clone();
    timings.0.extend(composited.timings.0);
    let mut notes = solved.notes.clone();
    // The solve and the composite each say so when they fall back to the CPU: one line is enough.
    for note in composited.notes {
        if !notes.contains(&note) {
            notes.push(note);
        }
    }
    Ok(Rendered { image: composited.image, solved: Some(solved), device: composited.device, notes, timings })
}
