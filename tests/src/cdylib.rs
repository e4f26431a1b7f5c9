//! Finding (and first building) libvolscatter for the cross-language tests.
//!
//! The tests run from `cargo nextest run --workspace` (or `cargo test`) on a clean clone, so
//! they cannot assume the cdylib was built: the first call runs
//! `cargo build -p volscatter --lib` with the profile and target directory of the running test
//! binary (so `CARGO_TARGET_DIR`, `--target-dir` and `--cargo-profile release` are all
//! honoured), once per test process. Cargo's own lock serialises concurrent callers; when the
//! library is up to date the build is a no-op.
//!
//! `VOLSCATTER_LIB`, when set to an existing file, is used as is and nothing is built (CI's
//! scripts/test.sh builds the release library first and exports it for the Python tests too).

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

/// The workspace root (parent of this crate).
pub fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().expect("tests/ has a parent").to_path_buf()
}

/// `<target>/<profile>` of the running test binary (`.../deps/<test>` -> `...`).
pub fn profile_dir() -> PathBuf {
    let exe = std::env::current_exe().expect("current_exe");
    let deps = exe.parent().expect("test binary in a directory");
    let dir = if deps.file_name().is_some_and(|n| n == "deps") { deps.parent().unwrap() } else { deps };
    dir.to_path_buf()
}

/// Cargo profile name of a profile directory: `debug` is `dev`.
fn profile_name(dir: &Path) -> String {
    match dir.file_name().and_then(|n| n.to_str()) {
        Some("debug") | None => "dev".into(),
        Some(other) => other.into(),
    }
}

pub const LIB_NAME: &str = if cfg!(target_os = "windows") {
    "volscatter.dll"
} else if cfg!(target_os = "macos") {
    "libvolscatter.dylib"
} else {
    "libvolscatter.so"
};

/// Builds the cdylib if needed and returns its path. Panics with cargo's output on failure.
pub fn cdylib() -> &'static Path {
    static PATH: OnceLock<PathBuf> = OnceLock::new();
    PATH.get_or_init(|| built("VOLSCATTER_LIB", &["--lib"], LIB_NAME))
}

/// Builds the `volscatter` CLI if needed (or takes `VOLSCATTER_BIN`) and returns its path.
pub fn cli_binary() -> &'static Path {
    static PATH: OnceLock<PathBuf> = OnceLock::new();
    PATH.get_or_init(|| built("VOLSCATTER_BIN", &["--bin", "volscatter"], if cfg!(windows) { "volscatter.exe" } else { "volscatter" }))
}

/// `env_var` when it names a file, else `cargo build -p volscatter <what>` with the running
/// test binary's profile and target directory, then `<profile dir>/<file>`.
fn built(env_var: &str, what: &[&str], file: &str) -> PathBuf {
    if let Some(path) = std::env::var_os(env_var).map(PathBuf::from).filter(|p| p.is_file()) {
        return path;
    }
    let dir = profile_dir();
    let target_dir = dir.parent().expect("profile dir has a parent");
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    let out = Command::new(&cargo)
        .current_dir(workspace_root())
        .args(["build", "-p", "volscatter"])
        .args(what)
        .args(["--profile", &profile_name(&dir), "--target-dir"])
        .arg(target_dir)
        .env("CARGO_TERM_COLOR", "never")
        .output()
        .unwrap_or_else(|e| panic!("running {cargo:?} build: {e}"));
    if !out.status.success() {
        panic!("cargo build -p volscatter {what:?} failed:\n{}", String::from_utf8_lossy(&out.stderr));
    }
    let path = dir.join(file);
    assert!(path.exists(), "{} missing after building", path.display());
    path
}

/// A fresh scratch directory under the target directory, named after the test.
pub fn scratch_dir(name: &str) -> PathBuf {
    let dir = profile_dir().join("volscatter-tests").join(format!("{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("create scratch dir");
    dir
}

/// Whether a program can be run (`prog --version` succeeds).
pub fn have_program(prog: &str) -> bool {
    Command::new(prog).arg("--version").output().is_ok_and(|o| o.status.success())
}
