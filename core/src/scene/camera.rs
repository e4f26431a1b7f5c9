//! Pinhole camera with a horizontal field of view, like Blender's and Mitsuba's (`fov_axis: x`).

use glam::Vec3;

#[derive(Clone, Debug)]
pub struct Camera {
    pub position: Vec3,
    /// Unit vectors: viewing direction, image right, image up.
    pub forward: Vec3,
    pub right: Vec3,
    pub up: Vec3,
    pub fov_deg: f32,
    pub width: u32,
    pub height: u32,
}

impl Camera {
    /// Caller validates: position != look_at, up not parallel to the view direction.
    pub fn look_at(position: Vec3, look_at: Vec3, up: Vec3, fov_deg: f32, width: u32, height: u32) -> Self {
        let forward = (look_at - position).normalize();
        let right = forward.cross(up).normalize();
        let up = right.cross(forward);
        Camera { position, forward, right, up, fov_deg, width, height }
    }

    /// Direction of the ray through continuous pixel coordinates (x right, y down, pixel (0,0)
    /// covering [0,1)^2).
    #[inline]
    pub fn ray_dir(&self, px: f32, py: f32) -> Vec3 {
        let tan_half = (0.5 * self.fov_deg.to_radians()).tan();
        let sx = (2.0 * px / self.width as f32 - 1.0) * tan_half;
        let sy = (1.0 - 2.0 * py / self.height as f32) * tan_half * self.height as f32 / self.width as f32;
        (self.forward + self.right * sx + self.up * sy).normalize()
    }
}
