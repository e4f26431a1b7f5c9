"""Rendering and baking USD stages with libvolscatter.

- :func:`render` -- one frame: stage -> scene JSON -> native scene -> image (EXR, optional PNG).
  Solver "reference" path-traces the image (``vs_scene_render_reference``); any other solver
  computes the scattering grid (``vs_scene_solve``) and ray-marches it (``vs_result_composite``).
- :func:`bake` -- solves each volume and writes its scattering grid S as VDBs beside a new USD
  layer that sublayers the stage and adds, per Volume, the OpenVDBAsset field ``scatter`` (one
  vec3s grid) and ``scatter_r``, ``scatter_g``, ``scatter_b`` (the library's float grids
  ``scattering_r/g/b``), and a material binding whose volume shader names them as emission
  (see usd/README.md).
"""

from __future__ import annotations

import os
import re
import struct
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Dict, List, Optional, Sequence

import numpy as np

from . import stage as stage_mod
from ._native import (STATUS_FORMAT, STATUS_IO, STATUS_UNSUPPORTED, Result, Scene, Session, VolscatterError, solvers,
                      write_vdb)
from .atomic import temp_beside, write_bytes_atomic

Progress = Optional[Callable[[str, float], Optional[bool]]]


def solver_lights() -> Dict[str, set]:
    """Each solver's light types (scene JSON types), from the library's solver registry."""
    return {s["name"]: set(s["lights"]) for s in solvers()["solvers"]}


@dataclass
class FrameResult:
    time: float
    out: str
    width: int
    height: int
    mean_rgb: List[float]
    mean_alpha: float
    warnings: List[str] = field(default_factory=list)
    #: What the ``auto`` solver picked and why (``Result.choice``); None for the other solvers.
    choice: Optional[dict] = None


def solver_warnings(scene: stage_mod.StageScene, solver: str) -> List[str]:
    """Lights in the scene the chosen solver leaves out (warned, never dropped silently)."""
    handled = solver_lights().get(solver)
    if handled is None:
        return []
    out = []
    for l in scene.lights:
        if l.json["type"] not in handled:
            out.append(f"solver {solver} does not handle {l.json['type']} lights yet: light {l.path} is left out of "
                       "the scattering (use --solver reference)")
    return out


def native_scene(doc: dict, solver: str, settings: Optional[dict]) -> Scene:
    """A native Scene from scene JSON, with the solver chosen."""
    s = Scene.from_json(doc)
    try:
        s.set_solver(solver, settings or None)
    except BaseException:
        s.close()
        raise
    return s


class FrameSessions:
    """The native sessions of a frame range (``--frames``): one :class:`Session` per volume,
    made from its first frame and kept for the rest, so that the solver reuses between frames
    what did not change (pop: the density mip, the dome importance and the dome's ordinates
    while only the sun or the local lights move). ``close()`` or ``with`` destroys them."""

    def __init__(self):
        self._sessions: Dict[str, Session] = {}

    def solve(self, scene: Scene, progress: Progress = None, key: str = "") -> Result:
        """Solves ``scene`` as the next frame of the session ``key`` (a volume's path)."""
        session = self._sessions.get(key)
        if session is None:
            session = self._sessions[key] = Session(scene)
        return session.solve(scene, progress)

    def frame_counts(self) -> Dict[str, int]:
        """Frames solved so far in each session."""
        return {k: s.frame_count for k, s in self._sessions.items()}

    def close(self):
        for s in self._sessions.values():
            s.close()
        self._sessions.clear()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False


def frame_path(pattern: str, frame: float) -> str:
    """``out.####.exr`` -> ``out.0012.exr``; ``out_{frame}.exr`` / ``out_{frame:04d}.exr`` ->
    Python formatting with the (integer when whole) frame number."""
    # An int stays exact (a float would name frame 2**63 - 1 ...808).
    f = frame if isinstance(frame, int) else int(frame) if float(frame).is_integer() else frame
    if "{frame" in pattern:
        return pattern.format(frame=f)
    m = re.search(r"#+", pattern)
    if m:
        width = len(m.group(0))
        s = f"{f:0{width}d}" if isinstance(f, int) else f"{f:0{width}.3f}"
        return pattern[:m.start()] + s + pattern[m.end():]
    return pattern


def has_frame_pattern(pattern: str) -> bool:
    return "{frame" in pattern or "#" in pattern


def _ensure_parent(path):
    d = os.path.dirname(os.path.abspath(path))
    os.makedirs(d, exist_ok=True)


def render(stage_path, out, png: Optional[str] = None, time=None, camera: Optional[str] = None,
           solver: str = "reference", settings: Optional[dict] = None, width: int = 320, height: Optional[int] = None,
           volume: Optional[str] = None, light_convention: str = "auto", medium_defaults: Optional[dict] = None,
           progress: Progress = None, png_exposure: float = 1.0, stage=None,
           warn: Optional[Callable[[str], None]] = None, transparent: bool = False,
           aovs=("background",), sessions: Optional[FrameSessions] = None) -> FrameResult:
    """Renders one frame of a stage into ``out`` (EXR: RGBA + AOVs) and optionally ``png``.
    ``transparent`` leaves the directly seen environment out (alpha from the medium only).
    ``aovs``: the compositor's layers in the EXR, as in ``volscatter render --aov`` (background
    by default: free; single and multiple cost a second light pass). The reference path
    tracer's image keeps all its layers (they cost it nothing).
    ``sessions``: the frame range's sessions, to solve this frame in (see :class:`FrameSessions`)."""
    sc = stage_mod.read_stage(stage_path, time=time, camera=camera, light_convention=light_convention,
                              medium_defaults=medium_defaults, stage=stage)
    warnings = list(sc.warnings) + solver_warnings(sc, solver)
    vi = pick_volume(sc, volume, warnings)
    doc = sc.scene_json(volume=vi, width=width, height=height)
    if warn:
        for w in warnings:
            warn(w)
    if transparent and solver == "reference":
        settings = dict(settings or {}, transparent=True)
    choice = None
    with native_scene(doc, solver, settings) as scene:
        if solver == "reference":
            image = scene.render_reference(progress)
        else:
            solved = sessions.solve(scene, progress, sc.volumes[vi].path) if sessions else scene.solve(progress)
            with solved as result:
                choice = result.choice()
                # What the library has to say (a fall-back to the CPU, a light left out): it never
                # prints, the host shows it.
                for note in result.notes():
                    warnings.append(note)
                    if warn:
                        warn(note)
                image = result.composite(transparent=transparent, aovs=aovs)
        with image:
            _ensure_parent(out)
            image.write_exr(out)
            rgba = image.rgba()
            w, h = image.size()
            if png:
                _ensure_parent(png)
                write_png(png, rgba, w, h, png_exposure, transparent)
    mean = _mean_rgba(rgba, w, h)
    return FrameResult(time=sc.time, out=str(out), width=w, height=h, mean_rgb=mean[:3], mean_alpha=mean[3],
                       warnings=warnings, choice=choice)


def pick_volume(sc: stage_mod.StageScene, volume: Optional[str], warnings: List[str]) -> int:
    if not sc.volumes:
        raise VolscatterError(f"{sc.stage_path}: the stage has no UsdVolVolume prim: nothing to render", 5)
    if volume:
        for i, v in enumerate(sc.volumes):
            if v.path == volume:
                return i
        raise VolscatterError(f"volume {volume} not found (volumes: {', '.join(v.path for v in sc.volumes)})", 2)
    if len(sc.volumes) > 1:
        warnings.append(f"the stage has {len(sc.volumes)} volumes; rendering {sc.volumes[0].path} only "
                        "(volscatter renders one medium at a time; pick with --volume)")
    return 0


def _mean_rgba(rgba, w, h) -> List[float]:
    try:
        import numpy as np
        if isinstance(rgba, np.ndarray):
            return [float(x) for x in rgba.reshape(-1, 4).mean(axis=0)]
    except ImportError:
        pass
    n = max(1, w * h)
    return [sum(rgba[i::4]) / n for i in range(4)]


# ----------------------------------------------------------------------------------------------
# PNG (sRGB, 8 bit RGBA) without dependencies beyond zlib; numpy when present

def _srgb(c: float) -> int:
    c = 0.0 if not c > 0.0 else (1.0 if c >= 1.0 else c)
    v = 12.92 * c if c <= 0.0031308 else 1.055 * c ** (1 / 2.4) - 0.055
    return int(round(v * 255.0))


def write_png(path, rgba, width: int, height: int, exposure: float = 1.0, transparent: bool = False):
    """Writes linear RGBA (rows top to bottom) as an sRGB PNG; colour times ``exposure``. The
    colour already holds the background (the seen environment), so the PNG is opaque unless
    ``transparent`` (then alpha = 1 - transmittance)."""
    try:
        import numpy as np
        a = np.asarray(rgba, dtype=np.float32).reshape(height, width, 4)
        rgb = np.clip(np.nan_to_num(a[..., :3] * exposure), 0.0, 1.0)
        srgb = np.where(rgb <= 0.0031308, 12.92 * rgb, 1.055 * np.power(rgb, 1 / 2.4) - 0.055)
        out = np.empty((height, width, 4), dtype=np.uint8)
        out[..., :3] = np.round(srgb * 255.0)
        out[..., 3] = np.round(np.clip(np.nan_to_num(a[..., 3]), 0.0, 1.0) * 255.0) if transparent else 255
        rows = b"".join(b"\0" + out[y].tobytes() for y in range(height))
    except ImportError:
        flat = list(rgba)
        rows = bytearray()
        for y in range(height):
            rows.append(0)
            for x in range(width):
                i = (y * width + x) * 4
                alpha = int(round(min(max(flat[i + 3], 0.0), 1.0) * 255)) if transparent else 255
                rows.extend([_srgb(flat[i] * exposure), _srgb(flat[i + 1] * exposure), _srgb(flat[i + 2] * exposure),
                             alpha])
        rows = bytes(rows)

    def chunk(tag, data):
        c = struct.pack(">I", len(data)) + tag + data
        return c + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF)

    png = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 6, 0, 0, 0))
    png += chunk(b"sRGB", b"\0") + chunk(b"IDAT", zlib.compress(rows, 6)) + chunk(b"IEND", b"")
    write_bytes_atomic(path, png)


# ----------------------------------------------------------------------------------------------
# bake

@dataclass
class BakeResult:
    layer: str
    vdbs: Dict[str, List[str]]     # volume path -> VDB files written (one per frame)
    warnings: List[str]


def _safe_name(path: str) -> str:
    return re.sub(r"[^A-Za-z0-9_]+", "_", path.strip("/")) or "volume"


def bake(stage_path, out_layer, times: Optional[Sequence[Optional[float]]] = None, camera: Optional[str] = None,
         solver: str = "reference", settings: Optional[dict] = None, width: int = 320, height: Optional[int] = None,
         light_convention: str = "auto", medium_defaults: Optional[dict] = None, progress: Progress = None,
         warn: Optional[Callable[[str], None]] = None, sessions: Optional[FrameSessions] = None) -> BakeResult:
    """Solves every Volume of the stage (at each time in ``times``; default: one solve at the
    default time) and writes ``out_layer``: a layer that sublayers the stage and adds the
    scattering fields. The VDBs go beside the layer, named ``<layer stem>.<volume>[.<frame>].vdb``.
    The scattering is computed towards the stage's camera (S is view-dependent for g != 0).
    Each volume's frames go through one native session (of ``sessions`` when given, else of
    sessions made here and closed on return)."""
    if sessions is None:
        with FrameSessions() as own:
            return bake(stage_path, out_layer, times, camera, solver, settings, width, height, light_convention,
                        medium_defaults, progress, warn, own)
    from pxr import Sdf
    src_stage = stage_mod.open_stage(stage_path)
    out_layer = os.path.abspath(out_layer)
    out_dir = os.path.dirname(out_layer)
    _check_layer_path(out_layer, Sdf)
    _ensure_dir(out_dir, "--out-layer")
    if os.path.abspath(stage_path) == out_layer:
        raise VolscatterError("--out-layer must not be the stage itself", 2)
    times = list(times) if times else [None]
    animated = len(times) > 1
    written: Dict[str, List[str]] = {}
    all_warnings: List[str] = []
    per_volume: Dict[str, List] = {}
    # Every VDB this bake writes is removed again if the bake fails or is cancelled before its
    # layer is saved: a VDB no layer points to is only clutter.
    made: List[str] = []
    try:
        for t in times:
            for b in bake_frame(stage_path, src_stage, out_layer, t, animated, camera=camera, solver=solver,
                                settings=settings, width=width, height=height, light_convention=light_convention,
                                medium_defaults=medium_defaults, progress=progress, warn=warn, sessions=sessions,
                                seen_warnings=all_warnings):
                made.append(b.path)
                written.setdefault(b.volume.path, []).append(b.path)
                per_volume.setdefault(b.volume.path, []).append((t, b.name, b.volume, b.copied))
        write_layer(stage_path, src_stage, out_layer, solver, per_volume, animated)
    except BaseException:
        for f in made:
            try:
                os.remove(f)
            except OSError:
                pass
        raise
    return BakeResult(layer=out_layer, vdbs=written, warnings=all_warnings)


def _check_layer_path(out_layer: str, Sdf):
    """Before anything is solved: a layer format USD writes, at a path that can be a file."""
    ext = os.path.splitext(out_layer)[1].lstrip(".")
    if not ext or not Sdf.FileFormat.FindByExtension(ext) or ext == "usdz":
        raise VolscatterError(f"--out-layer {out_layer}: not a USD layer USD can write (.usda, .usdc or .usd)", 2)
    if os.path.exists(out_layer) and not os.path.isfile(out_layer):
        raise VolscatterError(f"--out-layer {out_layer}: exists and is not a regular file", 2)


def _ensure_dir(d: str, what: str):
    """Creates folder ``d`` (and its parents) or says, naming it, why it cannot: a file on the
    way, or no permission to create or write in it."""
    for a in [d, *Path(d).parents]:
        if os.path.exists(a) and not os.path.isdir(a):
            raise VolscatterError(f"{what}: {a} is a file, not a folder", 2)
    try:
        os.makedirs(d, exist_ok=True)
    except OSError as e:
        raise VolscatterError(f"{what}: cannot create the folder {d}: {e.strerror}", 6)
    if not os.access(d, os.W_OK):
        raise VolscatterError(f"{what}: the folder {d} is not writable", 6)


@dataclass
class BakedVolume:
    """One Volume's VDB of one baked frame."""
    volume: stage_mod.VolumeInfo
    name: str          # the file's name, beside the layer
    path: str          # its absolute path
    copied: bool       # the density grid was copied into it


def bake_file_name(out_layer, volume_path: str, t: Optional[float], animated: bool) -> str:
    """``<layer stem>.<volume>[.<frame>].vdb``: the VDB of one Volume and frame, beside the layer."""
    name = f"{Path(out_layer).stem}.{_safe_name(volume_path)}"
    if animated and t is not None:
        name += f".{int(t) if float(t).is_integer() else t}"
    return f"{name}.vdb"


def bake_frame(stage_path, src_stage, out_layer, t: Optional[float], animated: bool, camera: Optional[str] = None,
               solver: str = "reference", settings: Optional[dict] = None, width: int = 320,
               height: Optional[int] = None, light_convention: str = "auto", medium_defaults: Optional[dict] = None,
               progress: Progress = None, warn: Optional[Callable[[str], None]] = None,
               sessions: Optional[FrameSessions] = None,
               seen_warnings: Optional[List[str]] = None) -> List[BakedVolume]:
    """Solves every Volume of the stage at time ``t`` in ``sessions`` (one per volume) and writes
    each one's VDB beside ``out_layer`` (atomically: the old file or the whole new one). Warnings
    not yet in ``seen_warnings`` go to ``warn`` and are added to it."""
    out_layer = os.path.abspath(out_layer)
    out_dir = os.path.dirname(out_layer)
    all_warnings = seen_warnings if seen_warnings is not None else []
    baked: List[BakedVolume] = []
    sc = stage_mod.read_stage(stage_path, time=t, camera=camera, light_convention=light_convention,
                              medium_defaults=medium_defaults, stage=src_stage)
    warnings = list(sc.warnings) + solver_warnings(sc, solver)
    if not sc.volumes:
        raise VolscatterError(f"{stage_path}: the stage has no UsdVolVolume prim: nothing to bake", 5)
    for w in warnings:
        if w not in all_warnings:
            all_warnings.append(w)
            if warn:
                warn(w)
    if sc.camera is None:
        msg = ("the stage has no camera: the scattering is solved towards a camera on -Y looking at each volume "
               "(exact for g = 0; pass --camera for anisotropic media)")
        if msg not in all_warnings:
            all_warnings.append(msg)
            if warn:
                warn(msg)
    for vi, v in enumerate(sc.volumes):
        if sc.camera is None:
            o = [v.object_to_world[3], v.object_to_world[7], v.object_to_world[11]]
            sc.camera = stage_mod.CameraInfo(path="(none)", position=[o[0], o[1] - 10.0, o[2]], look_at=o,
                                             up=[0.0, 0.0, 1.0], fov_deg=39.6, aspect=1.0, clipping=(0.0, 1e30))
        doc = sc.scene_json(volume=vi, width=width, height=height)
        fname = bake_file_name(out_layer, v.path, t, animated)
        with native_scene(doc, solver, settings) as scene, sessions.solve(scene, progress, v.path) as result:
            rgb = result.rgb()
            i2w = np.asarray(result.index_to_world(), dtype=np.float64).reshape(4, 4)
        # the grid in the Volume prim's local space (USD applies the prim's transform to
        # its fields), with the density copied in: one file per Volume and frame
        o2w = np.asarray(v.object_to_world, dtype=np.float64).reshape(4, 4)
        i2l = np.linalg.solve(o2w, i2w)
        grids = [("scatter", rgb), ("scattering_r", rgb[..., 0]), ("scattering_g", rgb[..., 1]),
                 ("scattering_b", rgb[..., 2])]
        i2l_flat = i2l.reshape(-1).tolist()
        try:
            write_vdb(os.path.join(out_dir, fname), grids, i2l_flat,
                      copies=[("density", v.vdb_path, v.field_name or "density")])
            copied = True
        except VolscatterError as e:
            if e.status not in (STATUS_FORMAT, STATUS_UNSUPPORTED):
                raise
            write_vdb(os.path.join(out_dir, fname), grids, i2l_flat)
            copied = False
            msg = (f"volume {v.path}: its density grid ({v.vdb_path}) could not be copied into the bake's VDB "
                   f"({e.message}); field:density keeps its own file (Blender's importer reads one file per "
                   "Volume)")
            all_warnings.append(msg)
            if warn:
                warn(msg)
        baked.append(BakedVolume(volume=v, name=fname, path=os.path.join(out_dir, fname), copied=bool(copied)))
    return baked


def write_layer(stage_path, src_stage, out_layer, solver: str, per_volume: Dict[str, List], animated: bool):
    """Writes the bake's layer: it sublayers the stage and, for each Volume of ``per_volume``
    (path -> [(time, VDB file name, VolumeInfo, density copied)]), adds the scattering fields and
    the material. Written beside under a temporary name and renamed over ``out_layer``, so that a
    failed write leaves the previous layer as it was."""
    from pxr import Sdf
    final_layer = os.path.abspath(out_layer)
    tmp = temp_beside(final_layer, keep_suffix=True)
    try:
        _compose_layer(stage_path, src_stage, tmp, solver, per_volume, animated)
        os.replace(tmp, final_layer)
    except VolscatterError:
        raise
    except Exception as e:  # pxr's Tf.ErrorException (a full disk, a denied folder), OSError
        raise VolscatterError(f"{final_layer}: the layer could not be written: {str(e).strip()}", STATUS_IO) from e
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)
    # A layer of this path open in this process would keep its old content.
    cached = Sdf.Layer.Find(final_layer)
    if cached:
        cached.Reload(force=True)


def _compose_layer(stage_path, src_stage, out_layer, solver: str, per_volume: Dict[str, List], animated: bool):
    """write_layer's layer, saved at ``out_layer`` (a temporary beside the final name)."""
    from pxr import Sdf, Usd, UsdGeom, UsdShade, UsdVol
    out_dir = os.path.dirname(out_layer)
    layer_stage = Usd.Stage.CreateNew(out_layer)
    root = layer_stage.GetRootLayer()
    rel = os.path.relpath(os.path.abspath(stage_path), out_dir)
    root.subLayerPaths.append(rel)
    src_root = src_stage.GetRootLayer()
    # stage metadata lives on the root layer only: carry it over
    for key in ("upAxis", "metersPerUnit", "defaultPrim", "startTimeCode", "endTimeCode", "timeCodesPerSecond",
                "framesPerSecond"):
        if src_root.pseudoRoot.HasInfo(key):
            root.pseudoRoot.SetInfo(key, src_root.pseudoRoot.GetInfo(key))
    root.documentation = f"volscatter bake of {os.path.basename(stage_path)} (solver {solver})"
    layer_stage = Usd.Stage.Open(root)  # recompose with the sublayer
    for vpath, entries in per_volume.items():
        vprim = layer_stage.GetPrimAtPath(vpath)
        if not vprim:
            vprim = layer_stage.OverridePrim(vpath)
        vol = UsdVol.Volume(vprim)

        def set_files(asset):
            fp = asset.CreateFilePathAttr()
            for t, fname, _v, _c in entries:
                if animated and t is not None:
                    fp.Set(Sdf.AssetPath("./" + fname), Usd.TimeCode(t))
                else:
                    fp.Set(Sdf.AssetPath("./" + fname))

        for field_name, grid, dtype in (("scatter", "scatter", "float3"), ("scatter_r", "scattering_r", "float"),
                                        ("scatter_g", "scattering_g", "float"), ("scatter_b", "scattering_b", "float")):
            fpath = Sdf.Path(vpath).AppendChild(field_name)
            asset = UsdVol.OpenVDBAsset.Define(layer_stage, fpath)
            asset.CreateFieldNameAttr().Set(grid)
            asset.CreateFieldDataTypeAttr().Set(dtype)
            if dtype == "float3":
                asset.CreateVectorDataRoleHintAttr().Set("Color")
            set_files(asset)
            vol.CreateFieldRelationship(field_name, fpath)
        if all(c for _t, _f, _v, c in entries):
            # the density, copied byte for byte into the same file: every field in one file
            dens = UsdVol.OpenVDBAsset(layer_stage.OverridePrim(entries[0][2].field_path))
            dens.CreateFieldNameAttr().Set("density")
            if dens.GetFieldIndexAttr().HasAuthoredValue():
                dens.GetFieldIndexAttr().Set(0)
            set_files(dens)
        # a material binding: the volume's emission is S per channel (W/m^3/sr), extinction is
        # density_scale * density, as volscatter computed it
        v = entries[0][2]
        # beside the Volume (a gprim's children are its fields), inside the same model
        mpath = Sdf.Path(vpath).GetParentPath().AppendChild(f"{Sdf.Path(vpath).name}_volscatterScatter")
        mat = UsdShade.Material.Define(layer_stage, mpath)
        sh = UsdShade.Shader.Define(layer_stage, mpath.AppendChild("ScatterEmission"))
        sh.CreateIdAttr("volscatter:ScatterEmission")
        sh.CreateInput("emission_field", Sdf.ValueTypeNames.Token).Set("scatter")
        sh.CreateInput("emission_r_field", Sdf.ValueTypeNames.Token).Set("scatter_r")
        sh.CreateInput("emission_g_field", Sdf.ValueTypeNames.Token).Set("scatter_g")
        sh.CreateInput("emission_b_field", Sdf.ValueTypeNames.Token).Set("scatter_b")
        sh.CreateInput("density_field", Sdf.ValueTypeNames.Token).Set(v.field_path.rsplit("/", 1)[-1])
        sh.CreateInput("density_scale", Sdf.ValueTypeNames.Color3f).Set(tuple(v.medium.density_scale))
        sh.CreateInput("albedo", Sdf.ValueTypeNames.Color3f).Set(tuple(v.medium.albedo))
        sh.CreateInput("anisotropy", Sdf.ValueTypeNames.Float).Set(v.medium.g)
        # S is per metre; per stage unit it is S * metersPerUnit
        sh.CreateInput("emission_scale", Sdf.ValueTypeNames.Float).Set(float(UsdGeom.GetStageMetersPerUnit(src_stage)))
        out = sh.CreateOutput("volume", Sdf.ValueTypeNames.Token)
        mat.CreateOutput("volume", Sdf.ValueTypeNames.Token).ConnectToSource(out)
        mat.GetPrim().SetDocumentation(
            "volscatter multiple scattering as emission: S = field scatter (RGB; or scatter_r/g/b) is in-scattered "
            "radiance per metre (W/m^3/sr, towards the camera it was solved for), S * emission_scale per stage unit; "
            "extinction = density_scale * density per metre")
        UsdShade.MaterialBindingAPI.Apply(vprim).Bind(mat)
        vprim.CreateAttribute("volscatter:bakedSolver", Sdf.ValueTypeNames.String, custom=True).Set(solver)
    if not layer_stage.GetRootLayer().Save():
        raise VolscatterError(f"{out_layer}: the layer could not be written", STATUS_IO)

