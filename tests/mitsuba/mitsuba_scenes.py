"""Shared scenes for comparing volscatter's `reference` path tracer with Mitsuba 3.

Each scene is described once (`SceneSpec`) and built twice: as volscatter scene JSON (format 1,
raw float32 density) and as a Mitsuba 3 scene dict (`scalar_rgb`, `volpath`). The conventions
follow the project notes on Mitsuba 3 as a reference (mitsuba-reference.md; summarised here where they
matter):

- Density: numpy array indexed [z][y][x], voxel (i,j,k) centred at `origin + (i,j,k) * voxel`,
  trilinear between centres, ramping to zero one voxel beyond the stored voxels (OpenVDB).
  Mitsuba's `gridvolume` is cell-centred on [0,1]^3, so the grid is padded with one zero voxel on
  every side and placed with `T = translate(min - voxel/2) * scale(N * voxel)` (N, min of the
  padded grid); the `cube` that carries the medium spans the same box.
- Lights: distant `irradiance` (W/m^2 perpendicular, `direction` = travel direction) ->
  `directional`; point `intensity` (W/sr) -> `point`; dome `color` (radiance) -> `constant`.
- Camera: horizontal `fov_deg` -> `perspective` with `fov_axis: x`; `box` pixel filter in both.

Used by test_agreement.py and by scripts/bench_reference.py.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

REPO_ROOT = Path(__file__).resolve().parents[2]


def volscatter_bin() -> Path:
    """The CLI under test: $VOLSCATTER_BIN, else target/release/volscatter in the repo."""
    env = os.environ.get("VOLSCATTER_BIN")
    return Path(env) if env else REPO_ROOT / "target" / "release" / "volscatter"


def import_mitsuba():
    """Mitsuba with the `scalar_rgb` variant, or None when it cannot be imported."""
    try:
        import mitsuba as mi
    except Exception:  # ImportError, or a broken native library
        return None
    mi.set_variant("scalar_rgb")
    # volpath warns about tiny negative samples (ratio-tracking round-off): keep the log quiet.
    mi.set_log_level(mi.LogLevel.Error)
    return mi


# --------------------------------------------------------------------------------------------
# Scenes


@dataclass
class SceneSpec:
    name: str
    density: np.ndarray  # [z][y][x] float32
    origin: tuple  # world centre of voxel (0,0,0)
    voxel: float
    density_scale: float
    albedo: list
    g: float
    lights: list  # volscatter light JSON objects
    camera: dict  # volscatter camera JSON object
    spp_ours: int  # per seed
    spp_mitsuba: int  # per seed
    seeds: tuple = (1, 2)
    extra: dict = field(default_factory=dict)


def _grid_coords(n: int):
    """World coordinates of the voxel centres of an n^3 grid spanning [-1, 1]^3."""
    voxel = 2.0 / n
    c = -1.0 + voxel * (np.arange(n) + 0.5)
    z, y, x = np.meshgrid(c, c, c, indexing="ij")
    return x, y, z, voxel, float(c[0])


def sphere_density(n: int = 32, radius: float = 0.8) -> tuple:
    """A homogeneous sphere (density 1), its edge anti-aliased over one voxel."""
    x, y, z, voxel, c0 = _grid_coords(n)
    r = np.sqrt(x * x + y * y + z * z)
    d = np.clip((radius - r) / voxel + 0.5, 0.0, 1.0)
    return d.astype(np.float32), voxel, c0


def cloud_density(n: int = 32) -> tuple:
    """A smooth, deliberately asymmetric procedural cloud (max 1): Gaussian puffs (the biggest
    right of centre and low, smaller ones upper left) modulated by smooth waves, with a soft
    radial window that reaches zero inside the grid."""
    x, y, z, voxel, c0 = _grid_coords(n)

    def blob(cx, cy, cz, s):
        return np.exp(-((x - cx) ** 2 + (y - cy) ** 2 + (z - cz) ** 2) / (2 * s * s))

    d = (blob(0.25, 0.05, -0.2, 0.28) + 0.8 * blob(-0.35, -0.1, 0.3, 0.2)
         + 0.6 * blob(-0.1, 0.2, -0.45, 0.18) + 0.5 * blob(0.45, -0.2, 0.35, 0.14))
    d *= 1.0 + 0.4 * np.sin(7.0 * x + 0.3) * np.sin(6.0 * y + 1.0) * np.sin(8.0 * z + 0.5)
    r = np.sqrt(x * x + y * y + z * z)
    d = np.clip(d * np.clip((0.95 - r) / 0.25, 0.0, 1.0), 0.0, None)
    return (d / d.max()).astype(np.float32), voxel, c0


def scenes() -> dict:
    """The agreement scenes, keyed by name."""
    sph, sv, s0 = sphere_density(32)
    cloud, cv, c0 = cloud_density(32)
    grid_cam = {"position": [0.3, -4.2, 0.6], "look_at": [0.0, 0.0, 0.0], "up": [0, 0, 1],
                "fov_deg": 36.0, "width": 64, "height": 48}
    return {
        "sphere_point": SceneSpec(
            name="sphere_point", density=sph, origin=(s0, s0, s0), voxel=sv,
            density_scale=2.5, albedo=[0.9, 0.75, 0.5], g=0.3,
            lights=[{"type": "point", "position": [0.3, -0.1, 0.2], "intensity": [3.0, 3.0, 3.0]}],
            camera={"position": [0.0, -4.0, 0.0], "look_at": [0.0, 0.0, 0.0], "up": [0, 0, 1],
                    "fov_deg": 35.0, "width": 48, "height": 48},
            spp_ours=1024, spp_mitsuba=1024),
        # A sphere lamp inside the medium, its interior dark: Mitsuba's one-sided sphere emitter
        # (docs/scene-format.md "Sphere lamps"). The pixels that see the lamp are masked
        # (`lamp_mask`): Mitsuba draws it, volscatter's images do not.
        "sphere_lamp": SceneSpec(
            name="sphere_lamp", density=sph, origin=(s0, s0, s0), voxel=sv,
            density_scale=2.5, albedo=[0.9, 0.75, 0.5], g=0.3,
            lights=[{"type": "point", "position": [0.3, -0.1, 0.2], "intensity": [3.0, 3.0, 3.0],
                     "radius": 0.25, "interior": "dark"}],
            camera={"position": [0.0, -4.0, 0.0], "look_at": [0.0, 0.0, 0.0], "up": [0, 0, 1],
                    "fov_deg": 35.0, "width": 48, "height": 48},
            spp_ours=1024, spp_mitsuba=1024),
        "grid_distant": SceneSpec(
            name="grid_distant", density=cloud, origin=(c0, c0, c0), voxel=cv,
            density_scale=12.0, albedo=[0.9, 0.9, 0.9], g=0.8,
            lights=[{"type": "distant", "direction": [-0.7, 0.3, -0.65], "irradiance": [3.0, 2.8, 2.5]}],
            camera=grid_cam, spp_ours=1024, spp_mitsuba=1024),
        "grid_dome": SceneSpec(
            name="grid_dome", density=cloud, origin=(c0, c0, c0), voxel=cv,
            density_scale=12.0, albedo=[0.9, 0.9, 0.9], g=0.8,
            lights=[{"type": "dome", "color": [0.25, 0.35, 0.55]}],
            camera=grid_cam, spp_ours=512, spp_mitsuba=512),
    }


# --------------------------------------------------------------------------------------------
# volscatter


def scene_json(spec: SceneSpec, raw_name: str, light_scale: float = 1.0) -> dict:
    """volscatter scene JSON; `light_scale` multiplies every light (for the units check)."""
    nz, ny, nx = spec.density.shape
    lights = []
    for light in spec.lights:
        light = dict(light)
        for key in ("irradiance", "intensity", "color"):
            if key in light:
                light[key] = [light_scale * v for v in light[key]]
        lights.append(light)
    return {
        "format": 1,
        "medium": {"raw": raw_name, "dims": [nx, ny, nz], "origin": list(spec.origin),
                   "voxel_size": spec.voxel, "density_scale": spec.density_scale,
                   "albedo": spec.albedo, "g": spec.g},
        "lights": lights,
        "camera": spec.camera,
        "solver": {"name": "reference", "max_depth": 1000, "rr_depth": 8},
    }


def read_exr_layers(path: Path) -> dict:
    """An EXR's RGB layers as float64 [height][width][3] arrays (via mitsuba.Bitmap), keyed by
    layer name: "rgb" for R,G,B, and "single", "multiple", "background" for our AOVs.
    Without Mitsuba (a lent GPU machine, where only a small wheel travels), through the OpenEXR
    package."""
    mi = import_mitsuba()
    if mi is not None:
        bmp = mi.Bitmap(str(path))
        data = np.asarray(bmp)
        channels = {f.name: data[..., i] for i, f in enumerate(bmp.struct_())}
    else:
        import OpenEXR

        with OpenEXR.File(str(path), separate_channels=True) as f:
            channels = {name: np.asarray(c.pixels) for name, c in f.channels().items()}
    layers = {}
    for prefix in sorted({n.rsplit(".", 1)[0] if "." in n else "" for n in channels}):
        chans = [f"{prefix}.{c}" if prefix else c for c in "RGB"]
        if all(c in channels for c in chans):
            layers[prefix or "rgb"] = np.stack([channels[c] for c in chans], -1).astype(np.float64)
    return layers


def read_exr_rgb(path: Path) -> np.ndarray:
    return read_exr_layers(path)["rgb"]


def render_ours(spec: SceneSpec, workdir: Path, seed: int, spp: int | None = None,
                light_scale: float = 1.0, layers: bool = False) -> tuple:
    """Renders with `volscatter render --solver reference`; returns (RGB image, report), or
    (dict of EXR layers, report) with `layers`."""
    workdir.mkdir(parents=True, exist_ok=True)
    raw = workdir / f"{spec.name}.f32"
    spec.density.astype("<f4").tofile(raw)
    tag = f"{spec.name}_s{seed}_x{light_scale:g}"
    scene_path = workdir / f"{tag}.json"
    scene_path.write_text(json.dumps(scene_json(spec, raw.name, light_scale), indent=1))
    out, report = workdir / f"{tag}.exr", workdir / f"{tag}.report.json"
    cmd = [str(volscatter_bin()), "render", str(scene_path), "--solver", "reference",
           "--out", str(out), "--spp", str(spp or spec.spp_ours), "--seed", str(seed),
           "--report", str(report), "-q", "--aov", "all"]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed ({proc.returncode}):\n{proc.stderr}")
    found = read_exr_layers(out)
    return (found if layers else found["rgb"]), json.loads(report.read_text())


# --------------------------------------------------------------------------------------------
# Mitsuba


def _rgb(v):
    return {"type": "rgb", "value": [float(c) for c in v]}


def mitsuba_dict(spec: SceneSpec, spp: int | None = None, max_depth: int = 1000) -> dict:
    """The Mitsuba scene. `max_depth` 2 keeps camera ray + one scattering vertex with its
    next-event estimate: single scattering plus the environment seen through the medium."""
    mi = import_mitsuba()
    T = mi.ScalarTransform4f
    # Pad one zero voxel on every side: the trilinear ramp to zero beyond the stored voxels.
    padded = np.pad(spec.density, 1).astype(np.float32)
    n = np.array(padded.shape[::-1], dtype=np.float64)  # x, y, z counts
    lo_centre = np.array(spec.origin, dtype=np.float64) - spec.voxel  # centre of padded voxel 0
    box_min = lo_centre - 0.5 * spec.voxel
    box_size = n * spec.voxel
    grid_to_world = T().translate(box_min.tolist()).scale(box_size.tolist())
    cube_to_world = T().translate((box_min + 0.5 * box_size).tolist()).scale((0.5 * box_size).tolist())
    medium = {
        "type": "heterogeneous",
        "albedo": _rgb(spec.albedo),
        "scale": float(spec.density_scale),
        "phase": {"type": "hg", "g": float(spec.g)},
        "sigma_t": {"type": "gridvolume", "grid": mi.VolumeGrid(padded[..., None].copy()),
                    "to_world": grid_to_world, "filter_type": "trilinear"},
    }
    cam = spec.camera
    d = {
        "type": "scene",
        "integrator": {"type": "volpath", "max_depth": max_depth, "rr_depth": 1000},
        "sensor": {
            "type": "perspective", "fov": float(cam["fov_deg"]), "fov_axis": "x",
            "to_world": T().look_at(origin=cam["position"], target=cam["look_at"], up=cam["up"]),
            "film": {"type": "hdrfilm", "width": cam["width"], "height": cam["height"],
                     "rfilter": {"type": "box"}, "pixel_format": "rgb"},
            "sampler": {"type": "independent", "sample_count": spp or spec.spp_mitsuba},
        },
        "medium": medium,
        "medium_box": {"type": "cube", "to_world": cube_to_world, "bsdf": {"type": "null"},
                       "interior": {"type": "ref", "id": "medium"}},
    }
    for i, light in enumerate(spec.lights):
        if light["type"] == "distant":
            e = {"type": "directional", "direction": light["direction"], "irradiance": _rgb(light["irradiance"])}
        elif light["type"] == "point" and light.get("radius", 0.0) > 0.0:
            if light.get("interior", "dark") != "dark":
                raise ValueError("Mitsuba's sphere emitter is one-sided: only a dark interior")
            r = float(light["radius"])
            # A transparent sphere in the medium whose surface emits I / (pi r^2) outwards.
            e = {"type": "sphere", "center": light["position"], "radius": r, "bsdf": {"type": "null"},
                 "interior": {"type": "ref", "id": "medium"}, "exterior": {"type": "ref", "id": "medium"},
                 "emitter": {"type": "area", "radiance": _rgb([c / (math.pi * r * r) for c in light["intensity"]])}}
        elif light["type"] == "point":
            e = {"type": "point", "position": light["position"], "intensity": _rgb(light["intensity"])}
        elif light["type"] == "dome":
            e = {"type": "constant", "radiance": _rgb(light["color"])}
        else:
            raise ValueError(f"no Mitsuba equivalent for light {light}")
        d[f"light_{i}"] = e
    return d


def lamp_mask(spec: SceneSpec) -> np.ndarray:
    """[height][width] True where a pixel may see a sphere lamp (its centre ray passes within the
    lamp's radius plus two pixels' footprint): Mitsuba draws the lamp, volscatter does not."""
    cam = spec.camera
    w, h = cam["width"], cam["height"]
    pos = np.array(cam["position"], dtype=np.float64)
    fwd = np.array(cam["look_at"], dtype=np.float64) - pos
    fwd /= np.linalg.norm(fwd)
    right = np.cross(fwd, np.array(cam["up"], dtype=np.float64))
    right /= np.linalg.norm(right)
    up = np.cross(right, fwd)
    t = math.tan(math.radians(cam["fov_deg"]) / 2.0)
    ys, xs = np.mgrid[0:h, 0:w]
    u = (2.0 * (xs + 0.5) / w - 1.0) * t
    v = (1.0 - 2.0 * (ys + 0.5) / h) * t * h / w
    d = fwd[None, None] + u[..., None] * right + v[..., None] * up
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    mask = np.zeros((h, w), dtype=bool)
    for light in spec.lights:
        r = light.get("radius", 0.0)
        if light["type"] != "point" or r <= 0.0:
            continue
        c = np.array(light["position"], dtype=np.float64) - pos
        along = d @ c
        miss = np.linalg.norm(c[None, None] - along[..., None] * d, axis=-1)
        pixel = 2.0 * t / w * np.linalg.norm(c)
        mask |= miss < r + 2.0 * pixel
    return mask


def render_mitsuba(spec: SceneSpec, seed: int, spp: int | None = None, max_depth: int = 1000) -> np.ndarray:
    mi = import_mitsuba()
    scene = mi.load_dict(mitsuba_dict(spec, spp, max_depth))
    img = mi.render(scene, seed=seed, spp=spp or spec.spp_mitsuba)
    return np.array(img, dtype=np.float64)[..., :3]


# --------------------------------------------------------------------------------------------
# Metrics
#
# A and B are each the average of two independent renders (seeds s1, s2): A = (a1 + a2) / 2.
# For independent, unbiased pixel estimates, E||a1 - a2||^2 = 2 sum_p var(a_p), so
# ||a1 - a2||^2 / 4 estimates sum_p var(A_p): the squared noise of the average. If A and B
# estimate the same image, E||A - B||^2 = sum var(A) + sum var(B), so the relative RMSE
# ||A - B|| / ||B|| that pure noise produces is
#     noise = sqrt(||a1 - a2||^2 + ||b1 - b2||^2) / (2 ||B||)
# (each term being the note's ||h1 - h2|| / (2 ||img||)). A systematic difference (bias) adds in
# quadrature: rel^2 ~ noise^2 + bias^2. Block averages (k x k pixels) keep a bias while dividing
# independent per-pixel noise by k, so they make the comparison sensitive to small biases.


def block_average(img: np.ndarray, k: int) -> np.ndarray:
    if k == 1:
        return img
    h, w = img.shape[0] // k * k, img.shape[1] // k * k
    return img[:h, :w].reshape(h // k, k, w // k, k, -1).mean(axis=(1, 3))


@dataclass
class Comparison:
    block: int
    rel_rmse: float  # ||A - B|| / ||B||
    noise_ours: float  # ||a1 - a2|| / (2 ||B||)
    noise_mitsuba: float  # ||b1 - b2|| / (2 ||B||)
    noise: float  # sqrt(noise_ours^2 + noise_mitsuba^2): rel_rmse expected from noise alone
    tolerance: float
    mean_ratio: float  # mean(A) / mean(B), all channels

    @property
    def ok(self) -> bool:
        return self.rel_rmse <= self.tolerance

    def __str__(self):
        return (f"block {self.block}: rel RMSE {self.rel_rmse:.4f}, noise {self.noise:.4f} "
                f"(ours {self.noise_ours:.4f}, Mitsuba {self.noise_mitsuba:.4f}), "
                f"tolerance {self.tolerance:.4f}, mean ratio {self.mean_ratio:.4f} -> "
                f"{'ok' if self.ok else 'FAIL'}")


# Tolerance = K_NOISE * noise + FLOOR.
# K_NOISE: with hundreds of blocks/pixels, ||A - B||^2 and the noise estimate are sums of many
# independent terms, each within ~10-15% of its mean for Gaussian noise; 1.5 leaves room for the
# heavy-tailed (firefly) noise of a point light inside a medium, while a bias b still fails once
# sqrt(noise^2 + b^2) > 1.5 noise + FLOOR, i.e. b > ~1.1 noise + FLOOR.
# FLOOR: room for differences that are neither noise nor bugs (float32 grids and lookups, the
# two renderers' different ray epsilons); 0.2% of the image norm. Measured: the dome scene,
# whose 8x8-block noise is 0.1%, agrees to 0.1%, so no systematic difference is visible above it.
K_NOISE = 1.5
FLOOR = 0.002


def compare(ours: tuple, theirs: tuple, block: int = 1) -> Comparison:
    """`ours` and `theirs`: two renders (different seeds) each."""
    a1, a2 = (block_average(x, block) for x in ours)
    b1, b2 = (block_average(x, block) for x in theirs)
    A, B = 0.5 * (a1 + a2), 0.5 * (b1 + b2)
    norm = np.linalg.norm(B)
    rel = np.linalg.norm(A - B) / norm
    na = np.linalg.norm(a1 - a2) / (2 * norm)
    nb = np.linalg.norm(b1 - b2) / (2 * norm)
    noise = float(np.hypot(na, nb))
    return Comparison(block, float(rel), float(na), float(nb), noise,
                      K_NOISE * noise + FLOOR, float(A.mean() / B.mean()))


def timed(f, *args, **kw):
    t = time.perf_counter()
    r = f(*args, **kw)
    return r, time.perf_counter() - t
