//! Light translation: the scene's lights as what the solvers consume (DESIGN.md, "Data flows").
//! One file per kind of translation:
//!
//! - `ordinates`: a distant light as one directional *ordinate* (direction of travel, fluence,
//!   initial anisotropy);
//! - `dome`: a dome as many ordinates over regions of equal importance (paper 01, Sec. 5.1),
//!   weighted by a directional importance map when the solver has one, and as a fixed set of
//!   importance-sampled directions (the compositor's single scattering);
//! - `emitters`: point, sphere and spot lights, and rect/disk area lights, as *point emitters*
//!   (a position, an intensity and an angular profile; area lights as VPLs);
//! - `emission`: an emissive medium as isotropic VPLs;
//! - `emitter_tree`: many point emitters as a tree whose far nodes are summed as one emitter;
//! - `sampling`: rays with their power drawn from any light (`LightSampler`), where photon
//!   tracing and VPL random walks start.
//!
//! Every solver and the compositor call these, so a light means the same thing everywhere.

pub mod dome;
pub mod emission;
pub mod emitter_tree;
pub mod emitters;
pub mod ordinates;
pub mod sampling;

pub use emitter_tree::EmitterTree;
pub use emitters::{area_vpls, local_emitters, scene_emitters, spot_emitter, Extent, PointEmitter, Profile};
pub use ordinates::{distant_ordinate, Ordinate};
pub use sampling::{LightRay, LightSampler};
