//! libvolscatter: the C ABI of volscatter (issue 4/9). For now it exposes only the version.

/// Library version, as in Cargo.toml.
pub const VERSION: &str = volscatter_core::VERSION;
