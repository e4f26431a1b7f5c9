"""Builds libvolscatter (the workspace's `plugin/` crate, a C library loaded with ctypes, not a
Python extension) with cargo through setuptools-rust and ships it in `volscatter/lib/`.

From the repository (`pip install ./usd`, `python -m build --wheel usd`) the crates are read where
they are, beside this folder. An sdist cannot hold files outside its folder, so `python -m build
usd` (an sdist, then a wheel from it) copies the crates the library needs into the sdist's
`rust/`, as a workspace of those crates only.
"""

import re
import shutil
from pathlib import Path

from setuptools import setup
from setuptools.command.sdist import sdist
from setuptools_rust import Binding, RustExtension

HERE = Path(__file__).resolve().parent
BUNDLED = HERE / "rust"
CRATES = ("core", "plugin", "shaders")


def workspace() -> Path:
    return BUNDLED if (BUNDLED / "plugin" / "Cargo.toml").is_file() else HERE.parent


class SdistWithCrates(sdist):
    def make_release_tree(self, base_dir, files):
        super().make_release_tree(base_dir, files)
        src, dst = workspace(), Path(base_dir) / "rust"
        for crate in CRATES:
            shutil.copytree(src / crate, dst / crate, ignore=shutil.ignore_patterns("target", "__pycache__"))
        shutil.copy2(src / "Cargo.lock", dst / "Cargo.lock")
        manifest = (src / "Cargo.toml").read_text()
        manifest, n = re.subn(r"(?m)^members = \[.*\]$", f"members = {list(CRATES)!r}".replace("'", '"'), manifest)
        if n != 1:
            raise RuntimeError("Cargo.toml: no one-line `members = [...]` to narrow to " + ", ".join(CRATES))
        (dst / "Cargo.toml").write_text(manifest)


setup(
    rust_extensions=[
        RustExtension(
            "volscatter.lib.libvolscatter",
            path=str(workspace() / "plugin" / "Cargo.toml"),
            binding=Binding.NoBinding,
            # plugin/Cargo.toml's own crate types, so that cargo finds fresh what `cargo build
            # --release` compiled (setuptools-rust would ask for the cdylib alone and rebuild).
            args=["--crate-type", "rlib,cdylib"],
        )
    ],
    cmdclass={"sdist": SdistWithCrates},
)
