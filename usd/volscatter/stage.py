"""Reading a USD stage (pxr) into volscatter's scene model (scene JSON, format 1).

Everything here is translation; the only native call lists a VDB's grids (libvolscatter's
``vs_vdb_info_json``, through :func:`vdb_grid_names`). Conventions (see usd/README.md):

* World: volscatter works in metres, Z up. Positions are multiplied by the stage's
  ``metersPerUnit``; a Y-up stage is turned +90 degrees about X (x, y, z) -> (x, -z, y), so
  that USD's +Y becomes +Z and the handedness is kept.
* Lights follow the UsdLux specification text (usdLux/schema.usda of OpenUSD 25.x, as shipped
  in usd-core): emitted radiance L = intensity * 2^exposure * color * blackbody(T) /
  sizeFactor, where sizeFactor is 1 unless ``normalize`` is on.

  - DistantLight (angular diameter ``angle``, theta = angle/2): irradiance on a plane facing
    the light E = L * pi sin^2(theta) for theta > 0. With ``normalize`` the sizeFactor is
    pi sin^2(theta), so E = intensity * 2^exposure * color (lux-like). At angle 0 the light
    is a delta direction and E = intensity * 2^exposure * color.
  - SphereLight (radius r, in metres after scaling): radiant intensity I = L * pi r^2
    (W/sr); with ``normalize`` the sizeFactor is the sphere's area 4 pi r^2, so
    I = intensity * 2^exposure * color / 4, independent of r. ``treatAsPoint`` keeps I and
    places a point (radius 0).
  - SphereLight with UsdLuxShapingAPI applied -> spot, unless ``shaping:cone:angle`` >= 180
    (no cut-off: a point). The spec's "light's primary axis" is the prim's -Z, as for every
    UsdLux emission direction. Shaping multiplies the emitted radiance and does not renormalise
    it, so the spot's axis intensity is the unshaped sphere's I above.
      * ``shaping:cone:angle`` (degrees off the axis, default 90; emission beyond it "is
        guaranteed to be zero") -> ``cone_half_angle_deg``. Note that the default of 90 on an
        applied ShapingAPI already cuts the back hemisphere, per the spec text.
      * ``shaping:cone:softness`` s (clamped to [0, 1]): UsdLux fades with
        1 - smoothstep(theta_off, a (1 - s), a) in the *angle*; volscatter's spot (Cycles'
        blend) is a smoothstep in the *cosine* from cos a up to cos_in = cos a + (1 - cos a)
        blend. Both end at a; we match the fade's midpoint (1/2 at the angle a (1 - s/2)):
        cos_in = 2 cos(a (1 - s/2)) - cos a, clamped to 1 (blend <= 1). The curves then differ
        by at most 0.04 of the axis intensity, and the cone's power by 0.6%, at a = 30 deg,
        s = 0.3; by 0.06 and 1.6% at a = 60 deg, s = 0.5; but a cosine smoothstep cannot start
        at the axis, so for s -> 1 the difference grows to 0.35 (1.6x the power at a = 30,
        s = 1). Where it exceeds 0.1 a warning gives it (``_cone_fade_difference``).
      * ``shaping:focus`` > 0 (|cos|^focus on the radiance) and ``shaping:focusTint``, and
        ``shaping:ies:file``: not representable; ignored with a warning.
    ShapingAPI with a cone or focus on any other light type: ignored with a warning.
  - RectLight (``width`` along the prim's local X, ``height`` along local Y, both scaled by the
    transform) -> rect emitting from its local -Z, tangent = local X. Radiance L (W/m^2/sr);
    with ``normalize`` the sizeFactor is the world-space area width * height. A
    ``texture:file`` is ignored (warning): the light is emitted with its uniform colour.
  - DiskLight (``radius`` in the XY plane, scaled by the transform) -> disk emitting from its
    local -Z, radiance L; with ``normalize`` sizeFactor = pi r^2 (world space). A
    non-uniformly scaled disk (an ellipse) becomes the disk of the same area, with a warning.
  - CylinderLight, GeometryLight, PortalLight, plugin lights: not supported; a warning names
    the prim and the light is left out.
  - DomeLight: radiance = intensity * 2^exposure * color (* texture); normalize is ignored.
  - Colour temperature (when enabled): UsdLuxBlackbodyTemperatureAsRgb(T) divided
    component-wise by its value at 6500 K, as the spec says ("normalized such that the default
    value of 6500 will always result in white"). pxr's function alone gives
    (1.043, 0.984, 1.035) at 6500 K; Blender writes enableColorTemperature = 1 at 6500 K on every
    light, which therefore stays white.

* Blender's USD exporter writes DistantLight intensity = sun strength / 4 (its importer
  multiplies by 4 again), while under UsdLux semantics a normalized distant light's intensity
  *is* the irradiance. For stages written by Blender (root layer ``doc`` "Blender v..." or
  ``userProperties:blender:*`` attributes; ``light_convention="auto"``), distant lights get the
  factor 4 back so that E equals the sun's strength in W/m^2, as Cycles renders it. Blender's
  SphereLight export (intensity = power / pi, normalize = 1) already agrees with UsdLux:
  I = (P / pi) / 4 = P / (4 pi) W/sr, Cycles' point light intensity. No factor there.
  Blender 5.0's spot and area lights (checked by exporting them with bpy):
  - a spot of power P, spot_size S, spot_blend b, radius r is a SphereLight with ShapingAPI:
    intensity P / pi, normalize 1, radius r, ``shaping:cone:angle`` = S / 2 and
    ``shaping:cone:softness`` = b (Blender's importer reads them back the same way). The
    intensity agrees with UsdLux (P / (4 pi) W/sr on the axis, as Cycles renders a spot of P
    watts), but softness holds Cycles' blend, a fade in the cosine: under the Blender
    convention blend = softness, not the angle-to-cosine mapping above.
  - an area light of power P is a RectLight (square, rectangle: width ``size``, height
    ``size_y``) or a DiskLight (disk: radius size / 2; ellipse: radius (size + size_y) / 4)
    with intensity P / pi and normalize 1: UsdLux radiance (P / pi) / A, Cycles' radiance
    P / (pi A). No factor there either; the ellipse's written disk has Blender's power, not
    its shape.
"""

from __future__ import annotations

import json
import math
import os
import re
import struct
from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, List, Optional, Sequence, Tuple

from ._native import VolscatterError, vdb_info

#: Medium defaults when neither the stage nor the caller gives a value.
DEFAULT_DENSITY_SCALE = 1.0
DEFAULT_ALBEDO = 1.0
DEFAULT_G = 0.0

#: Light types reported as unsupported (warned and left out).
UNSUPPORTED_LIGHT_TYPES = ("CylinderLight", "GeometryLight", "PortalLight", "PluginLight")


def _pxr():
    try:
        from pxr import Gf, Sdf, Usd, UsdGeom, UsdLux, UsdShade, UsdVol  # noqa: F401
    except ImportError as e:  # pragma: no cover - depends on the environment
        raise VolscatterError(f"the USD Python modules (pxr) are not installed: pip install usd-core ({e})") from e
    import pxr
    return pxr


# ----------------------------------------------------------------------------------------------
# small linear algebra on 3x3 / 4x4 row-major nested lists (column-vector convention)

def _matmul(a, b):
    n, m, p = len(a), len(b), len(b[0])
    return [[sum(a[i][k] * b[k][j] for k in range(m)) for j in range(p)] for i in range(n)]


def _apply3(m, v):
    return [sum(m[i][k] * v[k] for k in range(3)) for i in range(3)]


def _norm(v):
    n = math.sqrt(sum(x * x for x in v))
    return [x / n for x in v] if n > 0 else list(v)


def _gf_to_colmajor4(gm) -> List[List[float]]:
    """Gf.Matrix4d (row-vector convention, p' = p M) -> 4x4 for column vectors (M^T)."""
    return [[float(gm[j][i]) for j in range(4)] for i in range(4)]


def up_axis_matrix(up_axis: str) -> List[List[float]]:
    """3x3 rotation taking the stage's axes to volscatter's Z-up world."""
    if up_axis == "Y":
        return [[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]]
    return [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]


def blackbody_rgb(kelvin: float) -> Tuple[float, float, float]:
    """UsdLux colour temperature as an RGB multiplier, normalized so 6500 K is white."""
    from pxr import UsdLux
    t = min(max(float(kelvin), 1000.0), 10000.0)
    c = UsdLux.BlackbodyTemperatureAsRgb(t)
    w = UsdLux.BlackbodyTemperatureAsRgb(6500.0)
    return (c[0] / w[0], c[1] / w[1], c[2] / w[2])


# ----------------------------------------------------------------------------------------------
# small file-header readers: VDB grid names (through the library), EXR data window

def vdb_grid_names(path) -> List[Tuple[str, str]]:
    """(stored name, tree type) of every grid in an OpenVDB file, from its header as
    libvolscatter reads it (``vs_vdb_info_json``). Raises VolscatterError when the file is not
    a readable VDB."""
    info = vdb_info(path)
    return [(g["unique_name"], g["tree_type"] + ("_HalfFloat" if g["half"] else "")) for g in info["grids"]]


def exr_size(path) -> Optional[Tuple[int, int]]:
    """(width, height) of an OpenEXR file's data window, or None when unreadable."""
    try:
        with open(path, "rb") as f:
            data = f.read(1 << 16)
        if data[:4] != b"\x76\x2f\x31\x01":
            return None
        pos = 8
        while pos < len(data) and data[pos] != 0:
            end = data.index(b"\0", pos)
            name = data[pos:end]
            tend = data.index(b"\0", end + 1)
            size = struct.unpack("<i", data[tend + 1:tend + 5])[0]
            val = data[tend + 5:tend + 5 + size]
            if name == b"dataWindow":
                x0, y0, x1, y1 = struct.unpack("<4i", val[:16])
                return x1 - x0 + 1, y1 - y0 + 1
            pos = tend + 5 + size
    except (OSError, ValueError, struct.error):
        return None
    return None


# ----------------------------------------------------------------------------------------------
# what a stage holds

@dataclass
class MediumParams:
    density_scale: List[float]
    albedo: List[float]
    g: float
    #: where each value came from: "attribute volscatter:...", "material ...", "option", "default"
    source: Dict[str, str] = field(default_factory=dict)


@dataclass
class VolumeInfo:
    path: str
    field_path: str
    field_name: Optional[str]      # the grid name passed to the library
    vdb_path: str                  # absolute, resolved
    authored_path: str
    object_to_world: List[float]   # 16, row-major, metres, Z up (after the VDB's own map)
    medium: MediumParams

    def medium_json(self) -> dict:
        m = {"vdb": self.vdb_path, "density_scale": self.medium.density_scale, "albedo": self.medium.albedo,
             "g": self.medium.g, "transform": self.object_to_world}
        if self.field_name:
            m["grid"] = self.field_name
        return m


@dataclass
class LightInfo:
    path: str
    usd_type: str
    json: dict
    #: the numbers before unit conversion, for reports and tests
    detail: dict = field(default_factory=dict)


@dataclass
class CameraInfo:
    path: str
    position: List[float]
    look_at: List[float]
    up: List[float]
    fov_deg: float
    aspect: float                  # horizontal / vertical aperture
    clipping: Tuple[float, float]  # metres

    def json(self, width: int, height: int) -> dict:
        return {"position": self.position, "look_at": self.look_at, "up": self.up, "fov_deg": self.fov_deg,
                "width": int(width), "height": int(height)}


@dataclass
class StageScene:
    stage_path: str
    time: float                    # the time code read (nan for Default)
    up_axis: str
    meters_per_unit: float
    blender: bool                  # written by Blender's exporter
    light_convention: str          # "usdlux" or "blender" (as applied)
    volumes: List[VolumeInfo]
    lights: List[LightInfo]
    camera: Optional[CameraInfo]
    warnings: List[str]

    def scene_json(self, volume: int = 0, width: int = 320, height: Optional[int] = None,
                   solver: Optional[dict] = None) -> dict:
        """Scene JSON (format 1) for one volume."""
        if not self.volumes:
            raise VolscatterError(f"{self.stage_path}: the stage has no UsdVolVolume prim", 5)
        if self.camera is None:
            raise VolscatterError(f"{self.stage_path}: the stage has no Camera prim (a camera is needed to render)", 5)
        if height is None:
            height = max(1, round(width / self.camera.aspect))
        doc = {"format": 1, "medium": self.volumes[volume].medium_json(), "lights": [l.json for l in self.lights],
               "camera": self.camera.json(width, height)}
        # Finite attributes can still combine into infinity (intensity x 2^exposure, a huge
        # radius squared); JSON has no infinity, so it is named here, by prim, instead of
        # reaching the library as a parse error about a document the user never wrote.
        parts = [(self.volumes[volume].path, doc["medium"]), (self.camera.path, doc["camera"])]
        parts += [(l.path, l.json) for l in self.lights]
        for prim, part in parts:
            for key, value in part.items():
                nums = _numbers(value)
                # The library reads single precision: beyond 3.4e38 is infinity there.
                if nums is not None and not all(math.isfinite(x) and abs(x) <= _F32_MAX for x in nums):
                    raise VolscatterError(f"{prim}: the computed {key} {value} is not finite in single precision "
                                          "(check the prim's attributes)", 2)
        if solver:
            doc["solver"] = solver
        return doc


# ----------------------------------------------------------------------------------------------

def _smoothstep(x: float) -> float:
    x = min(max(x, 0.0), 1.0)
    return x * x * (3.0 - 2.0 * x)


def usdlux_softness_to_blend(cone_angle_deg: float, softness: float) -> float:
    """volscatter's (Cycles') spot blend whose fade, a smoothstep in the cosine, has its
    midpoint where UsdLux's fade in the angle has its own: at cone_angle * (1 - softness/2)."""
    if softness <= 0.0:
        return 0.0
    a = math.radians(cone_angle_deg)
    cos_outer = math.cos(a)
    cos_inner = min(2.0 * math.cos(a * (1.0 - 0.5 * softness)) - cos_outer, 1.0)
    return min(max((cos_inner - cos_outer) / (1.0 - cos_outer), 0.0), 1.0)


def _cone_fade_difference(cone_angle_deg: float, softness: float, blend: float, n: int = 400) -> float:
    """Largest difference between UsdLux's cone fade (softness) and volscatter's (blend), as
    fractions of the axis intensity, over the cone."""
    a = math.radians(cone_angle_deg)
    cos_outer = math.cos(a)
    cos_inner = cos_outer + (1.0 - cos_outer) * blend
    start = a * (1.0 - softness)
    worst = 0.0
    for i in range(n + 1):
        t = a * i / n
        usd = 1.0 - _smoothstep((t - start) / (a - start)) if a > start else 1.0
        ours = _smoothstep((math.cos(t) - cos_outer) / (cos_inner - cos_outer)) if cos_inner > cos_outer else 1.0
        worst = max(worst, abs(usd - ours))
    return worst


def open_stage(path):
    """Opens a stage; a missing or malformed file gives VolscatterError."""
    _pxr()
    from pxr import Tf, Usd
    p = Path(path)
    if not p.exists():
        raise VolscatterError(f"stage not found: {path}", 6)
    try:
        stage = Usd.Stage.Open(str(p))
    except Tf.ErrorException as e:
        # pxr repeats its source location for each of many parse errors: keep what they say,
        # the first few, at most 500 characters.
        msg = " ".join(str(e).split())
        msg = re.sub(r"Error in '[^']*' at line \d+ in file \S+ : ", "", msg)
        if len(msg) > 500:
            msg = msg[:500] + f"... ({len(msg) - 500} more characters)"
        raise VolscatterError(f"cannot open stage {path}: {msg}", 7) from e
    if stage is None:
        raise VolscatterError(f"cannot open stage {path}", 7)
    return stage


def _time_code(stage, time):
    from pxr import Usd
    if time is not None:
        return Usd.TimeCode(float(time))
    if stage.HasAuthoredTimeCodeRange():
        return Usd.TimeCode(stage.GetStartTimeCode())
    return Usd.TimeCode.Default()


def _is_blender(stage) -> bool:
    doc = stage.GetRootLayer().documentation or ""
    if doc.startswith("Blender"):
        return True
    for prim in stage.Traverse():
        for a in prim.GetAuthoredPropertyNames():
            if a.startswith("userProperties:blender:"):
                return True
    return False


_F32_MAX = 3.4028234663852886e38


def _where(attr) -> str:
    return f"{attr.GetPrim().GetPath()}: attribute {attr.GetName()}"


def _numbers(v):
    """The numbers in an attribute value (a scalar, a Gf vector or matrix, a tuple), or None
    when it holds something else (a string, an asset path)."""
    if isinstance(v, bool):
        return [float(v)]
    if isinstance(v, (int, float)):
        return [float(v)]
    if isinstance(v, (str, bytes)) or not hasattr(v, "__len__"):
        return None
    out = []
    try:
        for x in v:
            sub = _numbers(x)
            if sub is None:
                return None
            out.extend(sub)
    except TypeError:
        return None
    return out


def _get(attr, t, default=None):
    """The attribute's value at ``t``, or ``default`` when unauthored. Every value is checked
    here, where the prim and attribute are known: a NaN or infinity, or a value of another kind
    than ``default`` (a string where a number belongs, a number where a colour belongs), is a
    VolscatterError naming both (issue 22: they surfaced as JSON parse errors and tracebacks)."""
    if not attr or not attr.IsValid():
        return default
    v = attr.Get(t)
    if v is None:
        return default
    nums = _numbers(v)
    if nums is not None and not all(math.isfinite(x) for x in nums):
        raise VolscatterError(f"{_where(attr)} = {v} is not finite (NaN or infinity)", 2)
    if default is None:
        return v
    want = _numbers(default)
    if want is not None:
        if nums is None:
            raise VolscatterError(f"{_where(attr)} is {type(v).__name__} {str(v)[:200]!r}, a number is expected", 2)
        if len(want) > 1 and len(nums) not in (1, len(want)):
            raise VolscatterError(f"{_where(attr)} has {len(nums)} values, {len(want)} are expected", 2)
    elif isinstance(default, str) and not isinstance(v, str):
        raise VolscatterError(f"{_where(attr)} is {type(v).__name__} {str(v)[:200]!r}, a token or string is expected", 2)
    return v


def _asset(attr, t):
    """An asset-path attribute's value (None when unauthored); anything else authored under that
    name (an integer file path) is an error naming the prim and attribute."""
    v = _get(attr, t)
    if v is None:
        return None
    from pxr import Sdf
    if not isinstance(v, Sdf.AssetPath):
        raise VolscatterError(f"{_where(attr)} is {type(v).__name__} {str(v)[:200]!r}, an asset path is expected", 2)
    return v


def _rgb(v) -> List[float]:
    if isinstance(v, (int, float)):
        return [float(v)] * 3
    return [float(v[0]), float(v[1]), float(v[2])]


class _Reader:
    def __init__(self, stage, stage_path, time, light_convention, medium_defaults):
        from pxr import UsdGeom
        self.stage = stage
        self.stage_path = str(stage_path)
        self.t = _time_code(stage, time)
        self.warnings: List[str] = []
        self.up_axis = UsdGeom.GetStageUpAxis(stage)
        self.mpu = float(UsdGeom.GetStageMetersPerUnit(stage))
        if self.up_axis not in ("Y", "Z"):
            self.warnings.append(f"stage upAxis {self.up_axis!r} is not Y or Z: treated as Z")
            self.up_axis = "Z"
        self.C = up_axis_matrix(self.up_axis)
        self.blender = _is_blender(stage)
        if light_convention == "auto":
            light_convention = "blender" if self.blender else "usdlux"
        if light_convention not in ("usdlux", "blender"):
            raise VolscatterError(f"light convention {light_convention!r}: expected auto, usdlux or blender", 2)
        self.light_convention = light_convention
        self.medium_defaults = medium_defaults or {}

    # -- transforms
    def world4(self, prim) -> List[List[float]]:
        """prim's local-to-world at the time code, for column vectors, in volscatter's metres Z-up."""
        from pxr import UsdGeom
        m = _gf_to_colmajor4(UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(self.t))
        s = self.mpu
        conv = [[self.C[i][j] * s for j in range(3)] + [0.0] for i in range(3)] + [[0.0, 0.0, 0.0, 1.0]]
        return _matmul(conv, m)

    @staticmethod
    def point(m4, p=(0.0, 0.0, 0.0)):
        return [m4[i][0] * p[0] + m4[i][1] * p[1] + m4[i][2] * p[2] + m4[i][3] for i in range(3)]

    @staticmethod
    def direction(m4, d):
        return _norm([m4[i][0] * d[0] + m4[i][1] * d[1] + m4[i][2] * d[2] for i in range(3)])

    @staticmethod
    def linear_scale(m4) -> float:
        """Mean length of the transformed unit axes (metres per local unit)."""
        cols = [[m4[i][j] for i in range(3)] for j in range(3)]
        return sum(math.sqrt(sum(c * c for c in col)) for col in cols) / 3.0

    # -- volumes
    def volumes(self) -> List[VolumeInfo]:
        from pxr import Usd, UsdVol
        out = []
        from pxr import UsdGeom
        for prim in self.stage.Traverse(Usd.TraverseInstanceProxies()):
            if prim.IsA(UsdVol.Volume):
                if UsdGeom.Imageable(prim).ComputeVisibility(self.t) == UsdGeom.Tokens.invisible:
                    self.warnings.append(f"volume {prim.GetPath()} is invisible: left out")
                    continue
                out.append(self.volume(prim))
        return out

    def _pick_field(self, vol, prim) -> Tuple[str, object]:
        from pxr import UsdVol
        fields = vol.GetFieldPaths()  # {relationship name: target path}
        if not fields:
            raise VolscatterError(f"volume {prim.GetPath()} has no field:* relationship (no density field)", 5)
        cands = []
        for rel_name, path in sorted(fields.items()):
            fprim = self.stage.GetPrimAtPath(path)
            if not fprim or not fprim.IsValid():
                raise VolscatterError(f"volume {prim.GetPath()}: field:{rel_name} targets {path}, which does not exist", 5)
            cands.append((rel_name, fprim))
        for rel_name, fprim in cands:  # the relationship named density, else a field whose grid is density
            if rel_name == "density":
                return rel_name, fprim
        for rel_name, fprim in cands:
            if fprim.IsA(UsdVol.OpenVDBAsset) and _get(UsdVol.OpenVDBAsset(fprim).GetFieldNameAttr(), self.t) == "density":
                return rel_name, fprim
        rel_name, fprim = cands[0]
        self.warnings.append(f"volume {prim.GetPath()}: no field named density; using field:{rel_name} ({fprim.GetPath()})")
        return rel_name, fprim

    def volume(self, prim) -> VolumeInfo:
        from pxr import UsdVol
        vol = UsdVol.Volume(prim)
        rel_name, fprim = self._pick_field(vol, prim)
        if not fprim.IsA(UsdVol.OpenVDBAsset):
            raise VolscatterError(f"volume {prim.GetPath()}: field {fprim.GetPath()} is a {fprim.GetTypeName()}, "
                                  "only OpenVDBAsset fields are supported", 9)
        asset = UsdVol.OpenVDBAsset(fprim)
        fp_attr = asset.GetFilePathAttr()
        ap = _asset(fp_attr, self.t)
        if ap is None or not ap.path:
            raise VolscatterError(f"field {fprim.GetPath()} has no filePath at time {self._tstr()}", 5)
        resolved = ap.resolvedPath
        if not resolved or not os.path.isfile(resolved):
            layer_dir = None
            for spec in fp_attr.GetPropertyStack(self.t):
                layer_dir = os.path.dirname(spec.layer.realPath or "") or None
                break
            where = os.path.normpath(os.path.join(layer_dir, ap.path)) if layer_dir else ap.path
            raise VolscatterError(f"field {fprim.GetPath()}: VDB file {ap.path!r} not found (looked for {where})", 6)
        grids = vdb_grid_names(resolved)
        name = _get(asset.GetFieldNameAttr(), self.t) or None
        index_attr = asset.GetFieldIndexAttr()
        index = _get(index_attr, self.t, 0) if index_attr.HasAuthoredValue() else None
        base = [(g.split("\x1e")[0], g, ty) for g, ty in grids]
        if name:
            matching = [(g, ty) for b, g, ty in base if b == name]
            if not matching:
                listing = ", ".join(f"{b} ({ty})" for b, _, ty in base) or "no grids"
                raise VolscatterError(f"field {fprim.GetPath()}: fieldName {name!r} is not a grid of {resolved} (it has {listing})", 5)
            if index is not None:
                if not 0 <= int(index) < len(matching):
                    raise VolscatterError(f"field {fprim.GetPath()}: fieldIndex {index} out of range: {resolved} has "
                                          f"{len(matching)} grid(s) named {name!r}", 5)
                stored = matching[int(index)][0]
            else:
                stored = matching[0][0]
            gtype = dict(grids)[stored]
            if "float" not in gtype:
                raise VolscatterError(f"field {fprim.GetPath()}: grid {name!r} of {resolved} is {gtype}, a float grid is needed", 9)
            grid = stored
        else:
            grid = None
        if fprim.GetPath().GetParentPath() == prim.GetPath():
            from pxr import UsdGeom
            if UsdGeom.Xformable(fprim).GetOrderedXformOps():
                self.warnings.append(f"field {fprim.GetPath()} has its own xformOps; they are not applied (the volume's transform is)")
        m4 = self.world4(prim)
        flat = [m4[i][j] for i in range(4) for j in range(4)]
        return VolumeInfo(path=str(prim.GetPath()), field_path=str(fprim.GetPath()), field_name=grid,
                          vdb_path=os.path.abspath(resolved), authored_path=ap.path, object_to_world=flat,
                          medium=self.medium(prim))

    def _tstr(self):
        return "default" if self.t.IsDefault() else f"{self.t.GetValue():g}"

    def medium(self, prim) -> MediumParams:
        vals = {}
        src = {}
        for key, attr_name, kind in (("density_scale", "volscatter:densityScale", "rgb"),
                                     ("albedo", "volscatter:albedo", "rgb"), ("g", "volscatter:g", "float")):
            attr = prim.GetAttribute(attr_name)
            v = _get(attr, self.t, (1.0, 1.0, 1.0) if kind == "rgb" else 0.0) if attr and attr.HasAuthoredValue() else None
            if v is not None:
                vals[key] = _rgb(v) if kind == "rgb" else float(v if isinstance(v, (int, float)) else v[0])
                src[key] = f"attribute {attr_name}"
        mat = self.material_medium(prim)
        for key, v in mat.items():
            if key not in vals:
                vals[key], src[key] = v
        defaults = {"density_scale": DEFAULT_DENSITY_SCALE, "albedo": DEFAULT_ALBEDO, "g": DEFAULT_G}
        for key, d in defaults.items():
            if key in vals:
                continue
            if self.medium_defaults.get(key) is not None:
                v = self.medium_defaults[key]
                src[key] = "option"
            else:
                v = d
                src[key] = "default"
            vals[key] = v if key == "g" else _rgb(v)
        g = float(vals["g"])
        if not -1.0 < g < 1.0:
            raise VolscatterError(f"volume {prim.GetPath()}: g = {g} ({src['g']}) is outside (-1, 1)", 2)
        for c in vals["albedo"]:
            if not 0.0 <= c <= 1.0:
                raise VolscatterError(f"volume {prim.GetPath()}: albedo {vals['albedo']} ({src['albedo']}) is outside [0, 1]", 2)
        for c in vals["density_scale"]:
            if not (c >= 0.0 and math.isfinite(c)):
                raise VolscatterError(f"volume {prim.GetPath()}: densityScale {vals['density_scale']} ({src['density_scale']}) must be >= 0", 2)
        return MediumParams(density_scale=vals["density_scale"], albedo=vals["albedo"], g=g, source=src)

    def material_medium(self, prim) -> Dict[str, tuple]:
        """Medium parameters from the bound material, where readable: a shader on the
        material's ``volume`` output (any render context) with MaterialX ``anisotropic_vdf``
        inputs (absorption, scattering: coefficients per unit density; anisotropy), read as
        density_scale = absorption + scattering, albedo = scattering / density_scale, g =
        anisotropy. Other networks are not interpreted (noted in the warnings)."""
        from pxr import UsdShade
        mat, _rel = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial()
        if not mat:
            return {}
        outs = [o for o in mat.GetOutputs() if o.GetBaseName() == "volume"]
        for out in outs:
            srcs = out.GetConnectedSources()[0] if hasattr(out, "GetConnectedSources") else []
            for s in srcs:
                shader = UsdShade.Shader(s.source.GetPrim())
                if not shader:
                    continue
                ins = {i.GetBaseName(): i for i in shader.GetInputs()}
                if "absorption" in ins and "scattering" in ins:
                    a = _rgb(ins["absorption"].Get(self.t) or (0, 0, 0))
                    sc = _rgb(ins["scattering"].Get(self.t) or (0, 0, 0))
                    ds = [a[i] + sc[i] for i in range(3)]
                    al = [sc[i] / ds[i] if ds[i] > 0 else 1.0 for i in range(3)]
                    res = {"density_scale": (ds, f"material {mat.GetPath()}"), "albedo": (al, f"material {mat.GetPath()}")}
                    if "anisotropy" in ins and ins["anisotropy"].Get(self.t) is not None:
                        res["g"] = (float(ins["anisotropy"].Get(self.t)), f"material {mat.GetPath()}")
                    return res
        self.warnings.append(f"volume {prim.GetPath()}: bound material {mat.GetPath()} is not a network volscatter reads "
                             "(anisotropic_vdf on a volume output); medium parameters come from volscatter:* attributes or options")
        return {}

    # -- lights
    def lights(self) -> List[LightInfo]:
        from pxr import Usd, UsdGeom, UsdLux
        out = []
        for prim in self.stage.Traverse(Usd.TraverseInstanceProxies()):
            tname = str(prim.GetTypeName())
            if not prim.HasAPI(UsdLux.LightAPI):
                continue
            if UsdGeom.Imageable(prim) and UsdGeom.Imageable(prim).ComputeVisibility(self.t) == UsdGeom.Tokens.invisible:
                self.warnings.append(f"light {prim.GetPath()} is invisible: left out")
                continue
            if prim.IsA(UsdLux.DistantLight):
                out.append(self.distant(prim))
            elif prim.IsA(UsdLux.SphereLight):
                out.append(self.sphere(prim))
            elif prim.IsA(UsdLux.RectLight) or prim.IsA(UsdLux.DiskLight):
                info = self.rect(prim) if prim.IsA(UsdLux.RectLight) else self.disk(prim)
                if info is not None:
                    out.append(info)
            elif prim.IsA(UsdLux.DomeLight) or tname == "DomeLight_1":
                out.append(self.dome(prim))
            else:
                kind = tname or ", ".join(s for s in prim.GetAppliedSchemas() if "Light" in s) or "light"
                self.warnings.append(f"light {prim.GetPath()} ({kind}) is not supported by volscatter yet: left out")
        return out

    def _scalar(self, prim):
        """L' = intensity * 2^exposure * color * blackbody, and the parts."""
        from pxr import UsdLux
        api = UsdLux.LightAPI(prim)
        intensity = float(_get(api.GetIntensityAttr(), self.t, 1.0))
        exposure = float(_get(api.GetExposureAttr(), self.t, 0.0))
        color = _rgb(_get(api.GetColorAttr(), self.t, (1.0, 1.0, 1.0)))
        normalize = bool(_get(api.GetNormalizeAttr(), self.t, False))
        ct_on = bool(_get(api.GetEnableColorTemperatureAttr(), self.t, False))
        kelvin = float(_get(api.GetColorTemperatureAttr(), self.t, 6500.0))
        bb = blackbody_rgb(kelvin) if ct_on else (1.0, 1.0, 1.0)
        try:
            s = intensity * 2.0 ** exposure
        except OverflowError:
            raise VolscatterError(f"light {prim.GetPath()}: intensity {intensity} x 2^exposure ({exposure}) overflows", 2) from None
        rgb = [s * color[i] * bb[i] for i in range(3)]
        detail = {"intensity": intensity, "exposure": exposure, "color": color, "normalize": normalize,
                  "color_temperature": kelvin if ct_on else None, "blackbody": list(bb)}
        if prim.HasAPI(UsdLux.ShapingAPI) and not prim.IsA(UsdLux.SphereLight):
            sh = self._shaping(prim)
            if sh["cone_angle"] < 180.0 or sh["focus"] > 0.0 or sh["ies"]:
                self.warnings.append(f"light {prim.GetPath()}: ShapingAPI (cone/focus/IES) on a {prim.GetTypeName()} is "
                                     "not supported; emitted as unshaped")
        return rgb, normalize, detail

    def _shaping(self, prim) -> dict:
        """The UsdLuxShapingAPI inputs volscatter reads (spec defaults when unauthored)."""
        from pxr import UsdLux
        sh = UsdLux.ShapingAPI(prim)
        ies = _asset(sh.GetShapingIesFileAttr(), self.t)
        return {"cone_angle": float(_get(sh.GetShapingConeAngleAttr(), self.t, 90.0)),
                "cone_softness": float(_get(sh.GetShapingConeSoftnessAttr(), self.t, 0.0)),
                "focus": float(_get(sh.GetShapingFocusAttr(), self.t, 0.0)),
                "ies": str(ies.path) if ies is not None and ies.path else ""}

    def distant(self, prim) -> LightInfo:
        from pxr import UsdLux
        rgb, normalize, detail = self._scalar(prim)
        angle = float(_get(UsdLux.DistantLight(prim).GetAngleAttr(), self.t, 0.53))
        if angle >= 180.0:
            self.warnings.append(f"light {prim.GetPath()}: angle {angle} deg >= 180 is clamped to 179 (use a DomeLight)")
            angle = 179.0
        angle = max(angle, 0.0)
        theta = math.radians(angle) / 2.0
        size = math.pi * math.sin(theta) ** 2 if theta > 0 else 1.0
        # UsdLux: emitted radiance L = rgb / (size if normalize else 1), and a disc of radiance L
        # and angular radius theta gives E = L * pi sin^2(theta) = L * size on a facing plane.
        factor = 1.0 if (normalize or theta == 0) else size
        if self.light_convention == "blender":
            # Blender writes strength / 4 and half the sun's angular diameter (its default
            # 0.526 degree sun is written as 0.263): undo both.
            # Blender's importer ignores normalize, and so does this convention.
            factor = 4.0
            detail["blender_factor"] = 4.0
            angle = min(2.0 * angle, 179.0)
        m4 = self.world4(prim)
        direction = self.direction(m4, (0.0, 0.0, -1.0))
        irr = [c * factor for c in rgb]
        detail.update({"angle_deg": angle, "size_factor": size})
        return LightInfo(path=str(prim.GetPath()), usd_type="DistantLight",
                         json={"type": "distant", "direction": direction, "irradiance": irr, "angle_deg": angle},
                         detail=detail)

    def sphere(self, prim) -> LightInfo:
        from pxr import UsdLux
        rgb, normalize, detail = self._scalar(prim)
        light = UsdLux.SphereLight(prim)
        r_local = float(_get(light.GetRadiusAttr(), self.t, 0.5))
        as_point = bool(_get(light.GetTreatAsPointAttr(), self.t, False))
        m4 = self.world4(prim)
        r = abs(r_local) * self.linear_scale(m4)  # metres
        if normalize:
            intensity = [c / 4.0 for c in rgb]            # L = L'/(4 pi r^2), I = L pi r^2
        else:
            intensity = [c * math.pi * r * r for c in rgb]  # I = L pi r^2
            if r == 0:
                self.warnings.append(f"light {prim.GetPath()}: radius 0 without normalize emits nothing (UsdLux: L * pi r^2)")
        pos = self.point(m4)
        detail.update({"radius_m": r, "treat_as_point": as_point})
        js = {"type": "point", "position": pos, "intensity": intensity, "radius": 0.0 if as_point else r}
        if prim.HasAPI(UsdLux.ShapingAPI):
            js = self._spot(prim, m4, js, detail)
        return LightInfo(path=str(prim.GetPath()), usd_type="SphereLight", json=js, detail=detail)

    def _spot(self, prim, m4, point_json, detail) -> dict:
        """A shaped SphereLight: a spot along the prim's -Z (see the module's notes)."""
        sh = self._shaping(prim)
        detail["shaping"] = sh
        where = f"light {prim.GetPath()}"
        if sh["focus"] > 0.0:
            self.warnings.append(f"{where}: shaping:focus {sh['focus']:g} is not supported and was ignored")
        if sh["ies"]:
            self.warnings.append(f"{where}: IES profile {sh['ies']!r} is not supported and was ignored")
        angle = sh["cone_angle"]
        if angle >= 180.0:
            return point_json
        if angle <= 0.0:
            self.warnings.append(f"{where}: shaping:cone:angle {angle:g} emits nothing: left as a 0.01 degree cone")
        angle = max(angle, 0.01)
        softness = min(max(sh["cone_softness"], 0.0), 1.0)
        if self.light_convention == "blender":
            blend = softness  # Blender writes Cycles' spot_blend (a fade in the cosine) as the softness
        else:
            blend = usdlux_softness_to_blend(angle, softness)
            diff = _cone_fade_difference(angle, softness, blend)
            detail["cone_fade_difference"] = diff
            if diff > 0.1:
                self.warnings.append(f"{where}: shaping:cone:softness {softness:g} (a fade in the angle) is approximated "
                                     f"by a fade in the cosine; they differ by up to {diff:.2f} of the axis intensity")
        detail.update({"cone_half_angle_deg": angle, "blend": blend})
        return {"type": "spot", "position": point_json["position"], "direction": self.direction(m4, (0.0, 0.0, -1.0)),
                "intensity": point_json["intensity"], "cone_half_angle_deg": angle, "blend": min(max(blend, 0.0), 1.0),
                "radius": point_json["radius"]}

    @staticmethod
    def _axis_scales(m4) -> Tuple[float, float]:
        """Lengths of the prim's local X and Y axes in the world (metres per local unit)."""
        return tuple(math.sqrt(sum(m4[i][j] ** 2 for i in range(3))) for j in range(2))

    def rect(self, prim) -> Optional[LightInfo]:
        from pxr import UsdLux
        rgb, normalize, detail = self._scalar(prim)
        light = UsdLux.RectLight(prim)
        m4 = self.world4(prim)
        sx, sy = self._axis_scales(m4)
        w = abs(float(_get(light.GetWidthAttr(), self.t, 1.0))) * sx
        h = abs(float(_get(light.GetHeightAttr(), self.t, 1.0))) * sy
        tex = _get(light.GetTextureFileAttr(), self.t)
        if tex is not None and tex.path:
            self.warnings.append(f"light {prim.GetPath()}: RectLight texture {tex.path!r} is not supported; "
                                 "emitted with its uniform colour")
        area = w * h
        detail.update({"width_m": w, "height_m": h, "area_m2": area})
        if area <= 0.0:
            self.warnings.append(f"light {prim.GetPath()}: RectLight of zero area emits nothing: left out")
            return None
        radiance = [c / area for c in rgb] if normalize else rgb
        return LightInfo(path=str(prim.GetPath()), usd_type="RectLight",
                         json={"type": "rect", "position": self.point(m4), "normal": self.direction(m4, (0.0, 0.0, -1.0)),
                               "tangent": self.direction(m4, (1.0, 0.0, 0.0)), "size": [w, h], "radiance": radiance},
                         detail=detail)

    def disk(self, prim) -> Optional[LightInfo]:
        from pxr import UsdLux
        rgb, normalize, detail = self._scalar(prim)
        light = UsdLux.DiskLight(prim)
        m4 = self.world4(prim)
        sx, sy = self._axis_scales(m4)
        r_local = abs(float(_get(light.GetRadiusAttr(), self.t, 0.5)))
        if abs(sx - sy) > 1e-4 * max(sx, sy):
            self.warnings.append(f"light {prim.GetPath()}: a non-uniformly scaled DiskLight (an ellipse) is read as "
                                 "the disk of the same area")
        r = r_local * math.sqrt(sx * sy)  # the disk of the world-space area
        area = math.pi * r * r
        detail.update({"radius_m": r, "area_m2": area})
        if area <= 0.0:
            self.warnings.append(f"light {prim.GetPath()}: DiskLight of zero radius emits nothing: left out")
            return None
        radiance = [c / area for c in rgb] if normalize else rgb
        return LightInfo(path=str(prim.GetPath()), usd_type="DiskLight",
                         json={"type": "disk", "position": self.point(m4), "normal": self.direction(m4, (0.0, 0.0, -1.0)),
                               "radius": r, "radiance": radiance}, detail=detail)

    def dome(self, prim) -> LightInfo:
        from pxr import UsdLux
        rgb, _normalize, detail = self._scalar(prim)  # normalize is ignored for domes
        api = UsdLux.LightAPI(prim)
        intensity = detail["intensity"] * 2.0 ** detail["exposure"]  # _scalar has checked that this is finite
        tex_attr = prim.GetAttribute("inputs:texture:file")
        ap = _asset(tex_attr, self.t)
        if ap is not None and ap.path:
            resolved = ap.resolvedPath
            if not resolved or not os.path.isfile(resolved):
                raise VolscatterError(f"dome light {prim.GetPath()}: texture {ap.path!r} not found", 6)
            fmt = str(_get(prim.GetAttribute("inputs:texture:format"), self.t, "automatic"))
            if fmt not in ("automatic", "latlong"):
                self.warnings.append(f"dome light {prim.GetPath()}: texture format {fmt} is read as lat-long")
            tint = [rgb[i] / intensity if intensity else 0.0 for i in range(3)]
            size = exr_size(resolved)
            # Blender writes its world texture (in Blender's equirectangular layout, which is
            # volscatter's) on an unrotated DomeLight: taken as is under Blender's convention.
            if size != (1, 1) and self.light_convention != "blender" and not self._dome_matches_latlong(prim):
                self.warnings.append(
                    f"dome light {prim.GetPath()}: its orientation differs from volscatter's lat-long convention "
                    "(Z up, u = 0.5 - atan2(y, x) / 2pi); the map is used unrotated")
            js = {"type": "dome", "texture": os.path.abspath(resolved), "intensity": intensity}
            if any(abs(c - 1.0) > 1e-7 for c in tint):
                js["color"] = tint
            detail.update({"texture": resolved, "texture_size": size})
        else:
            js = {"type": "dome", "color": rgb}
        return LightInfo(path=str(prim.GetPath()), usd_type=str(prim.GetTypeName()), json=js, detail=detail)

    def _dome_matches_latlong(self, prim) -> bool:
        """Whether the dome's lat-long frame, in volscatter's world, is volscatter's own
        (USD latlong: pole +Y local, longitude 0 at +Z local, pi/2 at +X local)."""
        m4 = self.world4(prim)
        R = [[m4[i][j] for j in range(3)] for i in range(3)]
        s = self.linear_scale(m4) or 1.0
        R = [[v / s for v in row] for row in R]
        if str(prim.GetTypeName()) == "DomeLight_1":
            pole = str(_get(prim.GetAttribute("poleAxis"), self.t, "scene"))
            if pole == "Z" or (pole == "scene" and self.up_axis == "Z"):
                R = _matmul(R, [[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
        expected = [[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]
        return all(abs(R[i][j] - expected[i][j]) < 1e-3 for i in range(3) for j in range(3))

    # -- camera
    def camera(self, path: Optional[str]) -> Optional[CameraInfo]:
        from pxr import Sdf, Usd, UsdGeom
        if path:
            prim = self.stage.GetPrimAtPath(Sdf.Path(path)) if Sdf.Path.IsValidPathString(path) else None
            if not prim or not prim.IsValid():
                cams = [str(p.GetPath()) for p in self.stage.Traverse() if p.IsA(UsdGeom.Camera)]
                raise VolscatterError(f"camera {path} does not exist in {self.stage_path} "
                                      f"(cameras: {', '.join(cams) or 'none'})", 2)
            if not prim.IsA(UsdGeom.Camera):
                raise VolscatterError(f"{path} is a {prim.GetTypeName() or 'typeless prim'}, not a Camera", 2)
        else:
            prim = next((p for p in self.stage.Traverse(Usd.TraverseInstanceProxies()) if p.IsA(UsdGeom.Camera)), None)
            if prim is None:
                return None
        cam = UsdGeom.Camera(prim)
        proj = str(_get(cam.GetProjectionAttr(), self.t, "perspective"))
        if proj != "perspective":
            raise VolscatterError(f"camera {prim.GetPath()}: projection {proj!r} is not supported (perspective only)", 9)
        focal = float(_get(cam.GetFocalLengthAttr(), self.t, 50.0))
        hap = float(_get(cam.GetHorizontalApertureAttr(), self.t, 20.955))
        vap = float(_get(cam.GetVerticalApertureAttr(), self.t, 15.2908))
        if focal <= 0 or hap <= 0 or vap <= 0:
            raise VolscatterError(f"camera {prim.GetPath()}: focalLength and apertures must be > 0", 2)
        for a in ("horizontalApertureOffset", "verticalApertureOffset"):
            v = _get(prim.GetAttribute(a), self.t, 0.0)
            if v:
                self.warnings.append(f"camera {prim.GetPath()}: {a} = {v} (lens shift) is not supported and ignored")
        clip = _get(cam.GetClippingRangeAttr(), self.t, (1.0, 1000000.0))
        fov = math.degrees(2.0 * math.atan(hap / (2.0 * focal)))
        m4 = self.world4(prim)
        pos = self.point(m4)
        fwd = self.direction(m4, (0.0, 0.0, -1.0))
        up = self.direction(m4, (0.0, 1.0, 0.0))
        look = [pos[i] + fwd[i] for i in range(3)]
        return CameraInfo(path=str(prim.GetPath()), position=pos, look_at=look, up=up, fov_deg=fov, aspect=hap / vap,
                          clipping=(float(clip[0]) * self.mpu, float(clip[1]) * self.mpu))


def read_stage(path, time=None, camera: Optional[str] = None, light_convention: str = "auto",
               medium_defaults: Optional[dict] = None, stage=None) -> StageScene:
    """Reads a stage into a :class:`StageScene`. ``time``: a time code (default: the stage's
    start time code when it has one, else the default time). ``camera``: a prim path (default:
    the first Camera). ``medium_defaults``: {"density_scale", "albedo", "g"} used for volumes
    without ``volscatter:*`` attributes or a readable material."""
    if stage is None:
        stage = open_stage(path)
    r = _Reader(stage, path, time, light_convention, medium_defaults)
    volumes = r.volumes()
    lights = r.lights()
    cam = r.camera(camera)
    if cam and volumes:
        _check_clipping(r, cam, volumes)
    if not lights:
        r.warnings.append("the stage has no light volscatter supports: the medium will be dark")
    t = float("nan") if r.t.IsDefault() else float(r.t.GetValue())
    return StageScene(stage_path=str(path), time=t, up_axis=r.up_axis, meters_per_unit=r.mpu, blender=r.blender,
                      light_convention=r.light_convention, volumes=volumes, lights=lights, camera=cam,
                      warnings=r.warnings)


def _check_clipping(r: _Reader, cam: CameraInfo, volumes: Sequence[VolumeInfo]):
    """volscatter's pinhole has no clipping planes: say so when they would cut the volume."""
    from pxr import UsdGeom
    cache = UsdGeom.BBoxCache(r.t, [UsdGeom.Tokens.default_, UsdGeom.Tokens.render], useExtentsHint=True)
    for v in volumes:
        prim = r.stage.GetPrimAtPath(v.path)
        box = cache.ComputeWorldBound(prim).ComputeAlignedRange()
        if box.IsEmpty():
            continue
        corners = []
        for i in range(8):
            p = [box.GetMin()[k] if not (i >> k) & 1 else box.GetMax()[k] for k in range(3)]
            corners.append(_apply3(r.C, [c * r.mpu for c in p]))
        fwd = _norm([cam.look_at[i] - cam.position[i] for i in range(3)])
        depths = [sum((c[i] - cam.position[i]) * fwd[i] for i in range(3)) for c in corners]
        near, far = cam.clipping
        if min(depths) < near or max(depths) > far:
            r.warnings.append(f"camera {cam.path}: clipping range [{near:g}, {far:g}] m cuts volume {v.path} "
                              f"(depth {min(depths):.3g}..{max(depths):.3g} m); volscatter does not clip")


def time_range(stage) -> Tuple[float, float]:
    return float(stage.GetStartTimeCode()), float(stage.GetEndTimeCode())


def dumps(scene: StageScene) -> str:
    """A readable summary (for --verbose and debugging)."""
    d = {"stage": scene.stage_path, "time": None if math.isnan(scene.time) else scene.time, "upAxis": scene.up_axis,
         "metersPerUnit": scene.meters_per_unit, "blender": scene.blender, "light_convention": scene.light_convention,
         "volumes": [{"path": v.path, "field": v.field_path, "vdb": v.vdb_path, "grid": v.field_name,
                      "medium": {"density_scale": v.medium.density_scale, "albedo": v.medium.albedo, "g": v.medium.g,
                                 "source": v.medium.source}} for v in scene.volumes],
         "lights": [{"path": l.path, "type": l.usd_type, "scene": l.json} for l in scene.lights],
         "camera": None if scene.camera is None else {"path": scene.camera.path, "fov_deg": scene.camera.fov_deg,
                                                       "clipping_m": scene.camera.clipping},
         "warnings": scene.warnings}
    return json.dumps(d, indent=2)
