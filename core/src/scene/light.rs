//! Lights in the units of DESIGN.md, after host conventions have been converted.

use glam::Vec3;

use super::environment::Environment;

#[derive(Clone, Debug)]
pub enum Light {
    /// Light travelling along `direction` (unit), irradiance `irradiance` (W/m^2) on a plane
    /// perpendicular to it, from a disc of uniform radiance of angular radius `half_angle`
    /// (radians; 0 = a delta direction). The angle is kept, not its cosine: for the sun's
    /// 0.27 degrees, 1 - cos in f32 has a 1% error.
    Distant { direction: Vec3, irradiance: Vec3, half_angle: f32 },
    /// Intensity in W/sr. With `radius` > 0: a sphere of uniform radiance I / (pi r^2), which has
    /// the same power 4 pi I and looks the same from afar.
    Point { position: Vec3, intensity: Vec3, radius: f32 },
    Dome(Environment),
}
