//! File formats other than VDB: EXR (images out, environment maps in) and PNG previews, and the
//! checked file access (regular-file inputs, checked writes) every reader and writer uses.
pub mod exr;
pub mod files;
pub mod png;
