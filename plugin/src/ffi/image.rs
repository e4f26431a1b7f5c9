//! `VsImage`: an RGBA image with AOV layers, from compositing or path tracing.

use std::ffi::c_char;
use std::sync::Arc;

use volscatter_core::{io, Image};

use super::guard::{self, on_handle, out_slice, path_arg, str_arg, write_out};
use super::handle::{lock, Handle, Registry};
use super::status::{FfiError, FfiResult, VsStatus};

/// Opaque image handle, made by `vs_result_composite(_aovs)` or `vs_scene_render_reference`,
/// destroyed with `vs_image_destroy`.
pub struct VsImage {
    _private: [u8; 0],
}

pub(crate) struct ImageState {
    image: Image,
}

impl ImageState {
    pub fn new(image: Image) -> FfiResult<Self> {
        let n = image.width as usize * image.height as usize;
        if image.rgba.len() != n || image.aovs.iter().any(|(_, v)| v.len() != n) {
            return Err(FfiError::new(VsStatus::Internal, format!("image {}x{} has layers of the wrong size", image.width, image.height)));
        }
        Ok(ImageState { image })
    }
    fn pixels(&self) -> usize {
        self.image.width as usize * self.image.height as usize
    }
}

pub(crate) static IMAGES: Registry<ImageState, VsImage> = Registry::new("VsImage");

fn with_image(image: *const VsImage, body: impl FnOnce(&ImageState) -> FfiResult) -> VsStatus {
    on_handle(&IMAGES, image, |h: &Arc<Handle<ImageState>>| body(&lock(&h.state)))
}

/// Destroys an image. NULL is ignored; a dead handle gives `VS_STATUS_INVALID_HANDLE`.
///
/// Thread safety: any thread; the handle must not be used afterwards.
#[no_mangle]
pub unsafe extern "C" fn vs_image_destroy(image: *mut VsImage) -> VsStatus {
    guard::call(|| if image.is_null() { Ok(()) } else { IMAGES.remove(image) })
}

/// The message of the last failed call on this image ("" after a success); valid until the
/// next call on it or its destruction. For a NULL or dead handle, a static description.
///
/// Thread safety: meaningful only when no other thread calls functions on this image meanwhile.
#[no_mangle]
pub unsafe extern "C" fn vs_image_last_error(image: *const VsImage) -> *const c_char {
    guard::value(VsStatus::Internal.description().as_ptr().cast(), || match IMAGES.get(image) {
        Ok(h) => h.error.as_ptr(),
        Err(e) => e.status.description().as_ptr().cast(),
    })
}

/// Writes the image size in pixels to `*width` and `*height`.
///
/// Thread safety: any thread; calls on one image are serialised.
#[no_mangle]
pub unsafe extern "C" fn vs_image_size(image: *const VsImage, width: *mut u32, height: *mut u32) -> VsStatus {
    with_image(image, |s| {
        if width.is_null() || height.is_null() {
            return Err(FfiError::null(if width.is_null() { "width" } else { "height" }));
        }
        write_out(width, s.image.width, "width")?;
        write_out(height, s.image.height, "height")
    })
}

/// Copies the RGBA pixels (linear radiance, alpha = 1 - transmittance; rows top to bottom,
/// interleaved R, G, B, A) into `rgba`: `len` must equal width * height * 4.
///
/// Thread safety: any thread; calls on one image are serialised.
#[no_mangle]
pub unsafe extern "C" fn vs_image_copy_rgba(image: *const VsImage, rgba: *mut f32, len: usize) -> VsStatus {
    with_image(image, |s| {
        let needed = s.pixels().checked_mul(4).ok_or_else(|| FfiError::new(VsStatus::TooLarge, "image too large"))?;
        let out = out_slice(rgba, len, needed, "rgba")?;
        for (dst, p) in out.chunks_exact_mut(4).zip(&s.image.rgba) {
            dst.copy_from_slice(&p.to_array());
        }
        Ok(())
    })
}

/// Copies the AOV layer `name` (e.g. "single", "multiple", "background"; which exist depends
/// on how the image was made: `vs_result_composite_aovs` makes only the layers asked for) as interleaved RGB into `rgb`: `len` must equal
/// width * height * 3. An unknown name gives `VS_STATUS_INVALID_ARGUMENT` listing the layers.
///
/// Thread safety: any thread; calls on one image are serialised.
#[no_mangle]
pub unsafe extern "C" fn vs_image_copy_aov(image: *const VsImage, name: *const c_char, rgb: *mut f32, len: usize) -> VsStatus {
    with_image(image, |s| {
        let name = str_arg(name, "name")?;
        let Some(layer) = s.image.aov(name) else {
            let names: Vec<&str> = s.image.aovs.iter().map(|(n, _)| n.as_str()).collect();
            return Err(FfiError::invalid(format!("image has no layer `{name}` (layers: {})", names.join(", "))));
        };
        let needed = s.pixels().checked_mul(3).ok_or_else(|| FfiError::new(VsStatus::TooLarge, "image too large"))?;
        let out = out_slice(rgb, len, needed, "rgb")?;
        for (dst, p) in out.chunks_exact_mut(3).zip(layer) {
            dst.copy_from_slice(&p.to_array());
        }
        Ok(())
    })
}

/// Writes the image as float OpenEXR (RGBA plus every AOV as `name.R/G/B`) to `path`.
///
/// Thread safety: any thread; calls on one image are serialised.
#[no_mangle]
pub unsafe extern "C" fn vs_image_write_exr(image: *const VsImage, path: *const c_char) -> VsStatus {
    with_image(image, |s| {
        let path = path_arg(path, "path")?;
        io::exr::write_image(&path, &s.image)?;
        Ok(())
    })
}
