//! Cross-language and end-to-end tests live in `tests/`. Shared helpers:
//! [`cdylib`] builds and finds libvolscatter, [`vsapi`] loads it with libloading.

pub mod cdylib;
pub mod extreme;
pub mod vsapi;
