//! The README's Rust snippet, compiled with the workspace's examples so that it keeps working:
//! renders the embedded default scene with `pop` and writes an EXR.
//!
//!     cargo run --release -p volscatter-core --example render_default

use std::path::Path;

use volscatter_core::compositor::CompositeOptions;
use volscatter_core::pipeline::{self, Devices, Session};
use volscatter_core::stages::NoProgress;
use volscatter_core::Scene;

fn main() -> volscatter_core::Result<()> {
    let scene = Scene::default_scene(); // or Scene::load(Path::new("scene.json"))?
    let mut session = Session::new("pop", &Default::default(), Devices::cpu())?;
    let rendered = pipeline::render(&mut session, &scene, &CompositeOptions::default(), &NoProgress)?;
    volscatter_core::io::exr::write_image(Path::new("out.exr"), &rendered.image)
}
