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

    /// A file that can be decoded, but not for what was asked of it (e.g. a VDB grid copied
    /// byte for byte from a file version the writer does not write).
    #[error("{}: {message}", path.display())]
    Unsupported { path: PathBuf, message: String },

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

/// Longest piece of input quoted in a message. A 100 MB grid name must not become a 100 MB error
/// in the artist's console (issue 22).
pub const MAX_QUOTE_CHARS: usize = 200;

/// `text` for quoting in a message: whole when short, else its first [`MAX_QUOTE_CHARS`]
/// characters and how much was left out.
pub fn excerpt(text: &str) -> std::borrow::Cow<'_, str> {
    match text.char_indices().nth(MAX_QUOTE_CHARS) {
        None => std::borrow::Cow::Borrowed(text),
        Some((end, _)) => std::borrow::Cow::Owned(format!("{}... ({} more bytes)", &text[..end], text.len() - end)),
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn excerpt_keeps_short_text_and_cuts_long_text_on_a_char_boundary() {
        assert_eq!(super::excerpt("density"), "density");
        let long = "é".repeat(100_000);
        let e = super::excerpt(&long);
        assert!(e.chars().count() < super::MAX_QUOTE_CHARS + 40 && e.ends_with("(199600 more bytes)"), "{e}");
    }
}
