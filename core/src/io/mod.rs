//! File formats other than VDB: EXR (images out, environment maps in) and PNG previews.
pub mod exr;
pub mod png;
