//! One error type for the whole core. Every message names the field, file or value at fault,
//! because it ends up in front of a user (CLI, Blender report, Python exception).

use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// Scene description is invalid: `field` is a JSON path such as `lights[1].intensity`.
    #[error("scene: {field}: {message}")]
    Scene { field: String, message: String },

    #[error("{}: {source}", path.display())]
    Io { path: PathBuf, source: std::io::Error },

    /// A file that exists but cannot (or must not) be decoded.
    #[error("{}: {message}", path.display())]
    Format { path: PathBuf, message: String },

    /// A request that would need more memory than allowed (checked before allocating).
    #[error("too large: {0}")]
    TooLarge(String),

    #[error("invalid argument: {0}")]
    InvalidArgument(String),

    #[error("cancelled")]
    Cancelled,

    /// The device asked for failed: no adapter, a device request refused, out of device
    /// memory, a lost device, a kernel that failed. Hosts recognise GPU failures by this
    /// variant (never by the message), e.g. to fall back to the CPU.
    #[error("device: {0}")]
    Device(String),
}

pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    pub fn scene(field: impl Into<String>, message: impl Into<String>) -> Self {
        Error::Scene { field: field.into(), message: message.into() }
    }
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io { path: path.into(), source }
    }
    pub fn device(message: impl Into<String>) -> Self {
        Error::Device(message.into())
    }
    pub fn format(path: impl Into<PathBuf>, message: impl Into<String>) -> Self {
        Error::Format { path: path.into(), message: message.into() }
    }
}
