"""USD host (issue 6/9): reading stages into volscatter's scene, with the unit conversions pinned.

No native code runs here (pxr only): the Blender fixture, stages built with pxr holding each
light type with exposure / normalize / colour / colour temperature, transforms, upAxis,
metersPerUnit, medium attributes, field selection, and bad input.

Conventions pinned (derivations in usd/volscatter/stage.py and usd/README.md):
- DistantLight: E = intensity 2^exposure color, times pi sin^2(angle/2) unless normalize (or angle 0).
- SphereLight: I = intensity 2^exposure color / 4 with normalize, else times pi r^2 (metres).
- Blender-written stages: distant-light irradiance x4 and angle x2 (Blender writes strength / 4
  and half the angular diameter); SphereLight unchanged (power / pi under UsdLux is P / 4pi W/sr).
"""

import math
import os
import shutil
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
FIXTURES = ROOT.parent / "shared" / "fixtures"
BLENDER_STAGE = FIXTURES / "blender_noise_cube" / "scene.usda"

pxr = pytest.importorskip("pxr", reason="pxr (usd-core) is not installed: pip install usd-core")
from pxr import Gf, Sdf, Usd, UsdGeom, UsdLux, UsdVol  # noqa: E402

sys.path.insert(0, str(ROOT / "usd"))
from volscatter import VolscatterError  # noqa: E402
from volscatter import stage as S  # noqa: E402
from volscatter import render as R  # noqa: E402
from volscatter import cli as C  # noqa: E402

FOG = FIXTURES / "vdb" / "fog_blosc_full.vdb"
MINI = FIXTURES / "vdb" / "mini_zip.vdb"
TWO_GRIDS = FIXTURES / "vdb" / "vec3_and_density_blosc.vdb"


def approx(a, b, rel=1e-6, abs_=1e-9):
    return pytest.approx(b, rel=rel, abs=abs_) == a


def make_stage(tmp_path, name="s.usda", up="Z", mpu=1.0, vdb=FOG, with_camera=True, with_volume=True):
    """A stage with a volume (field density -> a copy of `vdb` beside the layer) and a camera."""
    path = tmp_path / name
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, up)
    UsdGeom.SetStageMetersPerUnit(stage, mpu)
    if with_volume:
        (tmp_path / "vol").mkdir(exist_ok=True)
        shutil.copy(vdb, tmp_path / "vol" / "d.vdb")
        vol = UsdVol.Volume.Define(stage, "/World/Smoke")
        f = UsdVol.OpenVDBAsset.Define(stage, "/World/Smoke/density")
        f.CreateFilePathAttr().Set(Sdf.AssetPath("./vol/d.vdb"))
        f.CreateFieldNameAttr().Set("density")
        vol.CreateFieldRelationship("density", f.GetPath())
    if with_camera:
        cam = UsdGeom.Camera.Define(stage, "/World/Cam")
        cam.CreateFocalLengthAttr().Set(50.0)
        cam.CreateHorizontalApertureAttr().Set(36.0)
        cam.CreateVerticalApertureAttr().Set(24.0)
    return stage, path


# ------------------------------------------------------------------------------------------------
# the Blender fixture

def test_blender_fixture_volume_field_transform():
    sc = S.read_stage(BLENDER_STAGE)
    assert sc.blender and sc.light_convention == "blender"
    assert sc.up_axis == "Z" and sc.meters_per_unit == 1.0
    assert len(sc.volumes) == 1
    v = sc.volumes[0]
    assert v.path == "/root/Volume/Volume" and v.field_path == "/root/Volume/Volume/density"
    # The same file, whether or not a folder on the way is a symbolic link (a checkout whose
    # ../shared is a link gives the asset path unresolved).
    assert Path(v.vdb_path).resolve() == (BLENDER_STAGE.parent / "volumes" / "Volume.vdb").resolve()
    assert v.field_name == "density"
    assert v.object_to_world == [1.0, 0, 0, 0, 0, 1.0, 0, 0, 0, 0, 1.0, 0, 0, 0, 0, 1.0]
    assert v.medium.source == {"density_scale": "default", "albedo": "default", "g": "default"}
    assert sc.warnings == []


def test_blender_fixture_sun_and_camera():
    sc = S.read_stage(BLENDER_STAGE)
    [sun] = sc.lights
    assert sun.path == "/root/Sun/Sun" and sun.usd_type == "DistantLight"
    assert sun.json["type"] == "distant"
    assert approx(sun.json["direction"], [0.0, 0.0, -1.0])
    # Blender's sun of strength 1 W/m^2 is written as intensity 0.25: irradiance 1 again.
    assert approx(sun.json["irradiance"], [1.0, 1.0, 1.0])
    # its default 0.526 degree disc is written as 0.263
    assert sun.json["angle_deg"] == pytest.approx(0.526, abs=1e-6)
    # enableColorTemperature = 1 at 6500 K: white under the spec's normalisation (no 1.043 tint)
    assert sun.detail["blackbody"] == pytest.approx([1.0, 1.0, 1.0], abs=1e-7)
    cam = sc.camera
    assert cam.path == "/root/Camera/Camera"
    assert approx(cam.position, [0.0, -6.0, 0.0], abs_=1e-5)
    fwd = [cam.look_at[i] - cam.position[i] for i in range(3)]
    assert approx(fwd, [0.0, 1.0, 0.0], abs_=1e-5)
    assert approx(cam.up, [0.0, 0.0, 1.0], abs_=1e-5)
    assert cam.fov_deg == pytest.approx(math.degrees(2 * math.atan(0.36 / (2 * 0.5))), rel=1e-6)
    assert cam.fov_deg == pytest.approx(39.5978, abs=1e-3)
    assert cam.aspect == pytest.approx(0.36 / 0.2025, rel=1e-6)
    assert cam.clipping == pytest.approx((0.1, 1000.0), rel=1e-6)


def test_blender_fixture_plain_usdlux_reading():
    sc = S.read_stage(BLENDER_STAGE, light_convention="usdlux")
    [sun] = sc.lights
    # normalize = 1: E = intensity (what another UsdLux reader sees: 4x darker than Cycles)
    assert approx(sun.json["irradiance"], [0.25, 0.25, 0.25])
    assert sun.json["angle_deg"] == pytest.approx(0.263, abs=1e-6)


def test_blender_fixture_scene_json_shape():
    sc = S.read_stage(BLENDER_STAGE)
    doc = sc.scene_json(width=64, height=48)
    assert doc["format"] == 1 and doc["camera"]["width"] == 64 and doc["camera"]["height"] == 48
    assert doc["medium"]["grid"] == "density" and os.path.isabs(doc["medium"]["vdb"])
    # default height from the camera's aperture ratio (16:9)
    assert sc.scene_json(width=320)["camera"]["height"] == 180


# ------------------------------------------------------------------------------------------------
# lights built with pxr

def _light(stage, cls, path, **attrs):
    l = cls.Define(stage, path)
    api = UsdLux.LightAPI(l.GetPrim())
    for k, v in attrs.items():
        {"intensity": api.CreateIntensityAttr, "exposure": api.CreateExposureAttr, "color": api.CreateColorAttr,
         "normalize": api.CreateNormalizeAttr, "ct": api.CreateColorTemperatureAttr,
         "ct_on": api.CreateEnableColorTemperatureAttr}[k]().Set(v)
    return l


def _by_path(sc, path):
    return next(l for l in sc.lights if l.path == path)


def test_distant_light_units(tmp_path):
    stage, path = make_stage(tmp_path)
    col = Gf.Vec3f(1.0, 0.5, 0.25)
    _light(stage, UsdLux.DistantLight, "/L/delta", intensity=3.0, exposure=1.0, color=col).CreateAngleAttr().Set(0.0)
    _light(stage, UsdLux.DistantLight, "/L/wide", intensity=3.0, exposure=1.0, color=col).CreateAngleAttr().Set(10.0)
    _light(stage, UsdLux.DistantLight, "/L/norm", intensity=3.0, exposure=1.0, color=col,
           normalize=True).CreateAngleAttr().Set(10.0)
    _light(stage, UsdLux.DistantLight, "/L/neg", intensity=2.0, exposure=-3.0).CreateAngleAttr().Set(0.0)
    stage.Save()
    sc = S.read_stage(path)
    assert not sc.blender and sc.light_convention == "usdlux"
    base = [6.0, 3.0, 1.5]  # 3 * 2^1 * color
    assert approx(_by_path(sc, "/L/delta").json["irradiance"], base)
    k = math.pi * math.sin(math.radians(5.0)) ** 2
    assert approx(_by_path(sc, "/L/wide").json["irradiance"], [c * k for c in base])
    assert approx(_by_path(sc, "/L/norm").json["irradiance"], base)
    assert _by_path(sc, "/L/norm").json["angle_deg"] == pytest.approx(10.0)
    assert approx(_by_path(sc, "/L/neg").json["irradiance"], [0.25] * 3)
    # the light travels along its -Z axis
    assert approx(_by_path(sc, "/L/delta").json["direction"], [0.0, 0.0, -1.0])


def test_distant_light_direction_from_transform(tmp_path):
    stage, path = make_stage(tmp_path)
    l = _light(stage, UsdLux.DistantLight, "/L/sun", intensity=1.0)
    UsdGeom.Xformable(l).AddRotateXOp().Set(90.0)    # -Z -> +Y
    l2 = _light(stage, UsdLux.DistantLight, "/L/side", intensity=1.0)
    UsdGeom.Xformable(l2).AddRotateYOp().Set(90.0)   # -Z -> -X
    UsdGeom.Xformable(l2).AddTranslateOp().Set(Gf.Vec3d(100, 0, 0))  # position is irrelevant
    stage.Save()
    sc = S.read_stage(path)
    assert approx(_by_path(sc, "/L/sun").json["direction"], [0.0, 1.0, 0.0], abs_=1e-6)
    assert approx(_by_path(sc, "/L/side").json["direction"], [-1.0, 0.0, 0.0], abs_=1e-6)


def test_sphere_light_units(tmp_path):
    stage, path = make_stage(tmp_path)
    a = _light(stage, UsdLux.SphereLight, "/L/norm", intensity=8.0, normalize=True)
    a.CreateRadiusAttr().Set(0.5)
    b = _light(stage, UsdLux.SphereLight, "/L/plain", intensity=8.0)
    b.CreateRadiusAttr().Set(0.5)
    c = _light(stage, UsdLux.SphereLight, "/L/point", intensity=8.0, normalize=True)
    c.CreateRadiusAttr().Set(0.1)
    c.CreateTreatAsPointAttr().Set(True)
    d = _light(stage, UsdLux.SphereLight, "/L/scaled", intensity=8.0, exposure=1.0)
    d.CreateRadiusAttr().Set(0.5)
    UsdGeom.Xformable(d).AddTranslateOp().Set(Gf.Vec3d(1, 2, 3))
    UsdGeom.Xformable(d).AddScaleOp().Set(Gf.Vec3f(2, 2, 2))
    stage.Save()
    sc = S.read_stage(path)
    n = _by_path(sc, "/L/norm").json
    assert n["type"] == "point" and approx(n["intensity"], [2.0] * 3) and n["radius"] == pytest.approx(0.5)
    assert approx(_by_path(sc, "/L/plain").json["intensity"], [8.0 * math.pi * 0.25] * 3)
    p = _by_path(sc, "/L/point").json
    assert p["radius"] == 0.0 and approx(p["intensity"], [2.0] * 3)
    s = _by_path(sc, "/L/scaled").json
    assert approx(s["position"], [1.0, 2.0, 3.0]) and s["radius"] == pytest.approx(1.0)
    assert approx(s["intensity"], [16.0 * math.pi * 1.0] * 3)


def test_blender_point_light_is_power_over_4pi(tmp_path):
    """Blender writes a point light of power P as intensity P/pi, normalize 1, treatAsPoint:
    UsdLux then gives P/(4 pi) W/sr, Cycles' intensity. Both conventions agree."""
    stage, path = make_stage(tmp_path)
    stage.GetRootLayer().documentation = "Blender v5.0.1"
    P = 100.0
    l = _light(stage, UsdLux.SphereLight, "/L/lamp", intensity=P / math.pi, normalize=True, ct_on=True, ct=6500.0)
    l.CreateRadiusAttr().Set(0.1)
    l.CreateTreatAsPointAttr().Set(True)
    stage.Save()
    for conv in ("auto", "usdlux", "blender"):
        sc = S.read_stage(path, light_convention=conv)
        assert approx(_by_path(sc, "/L/lamp").json["intensity"], [P / (4 * math.pi)] * 3, rel=1e-6)
    assert S.read_stage(path).light_convention == "blender"


def test_dome_light_colour_and_texture(tmp_path):
    stage, path = make_stage(tmp_path)
    _light(stage, UsdLux.DomeLight, "/L/sky", intensity=0.5, exposure=2.0, color=Gf.Vec3f(0.2, 0.4, 1.0),
           normalize=True)
    stage.Save()
    sc = S.read_stage(path)
    d = _by_path(sc, "/L/sky").json
    assert d == {"type": "dome", "color": pytest.approx([0.4, 0.8, 2.0])}  # normalize ignored for domes


def test_colour_temperature(tmp_path):
    stage, path = make_stage(tmp_path)
    _light(stage, UsdLux.DistantLight, "/L/d65", intensity=1.0, ct_on=True, ct=6500.0).CreateAngleAttr().Set(0.0)
    _light(stage, UsdLux.DistantLight, "/L/warm", intensity=1.0, ct_on=True, ct=3000.0).CreateAngleAttr().Set(0.0)
    _light(stage, UsdLux.DistantLight, "/L/off", intensity=1.0, ct_on=False, ct=3000.0).CreateAngleAttr().Set(0.0)
    stage.Save()
    sc = S.read_stage(path)
    assert approx(_by_path(sc, "/L/d65").json["irradiance"], [1.0, 1.0, 1.0], rel=1e-6)
    w = UsdLux.BlackbodyTemperatureAsRgb(3000.0)
    ref = UsdLux.BlackbodyTemperatureAsRgb(6500.0)
    warm = _by_path(sc, "/L/warm").json["irradiance"]
    assert approx(warm, [w[i] / ref[i] for i in range(3)], rel=1e-6)
    assert warm[0] > 1.0 > warm[2]
    assert approx(_by_path(sc, "/L/off").json["irradiance"], [1.0, 1.0, 1.0])


def test_unsupported_lights_warn_by_name(tmp_path):
    stage, path = make_stage(tmp_path)
    UsdLux.CylinderLight.Define(stage, "/L/tube")
    _light(stage, UsdLux.DistantLight, "/L/sun", intensity=1.0)
    stage.Save()
    sc = S.read_stage(path)
    assert [l.path for l in sc.lights] == ["/L/sun"]
    assert any("/L/tube" in w and "CylinderLight" in w and "not supported" in w for w in sc.warnings), sc.warnings


def _shape(light, **attrs):
    sh = UsdLux.ShapingAPI.Apply(light.GetPrim())
    for k, v in attrs.items():
        {"angle": sh.CreateShapingConeAngleAttr, "softness": sh.CreateShapingConeSoftnessAttr,
         "focus": sh.CreateShapingFocusAttr}[k]().Set(v)
    return sh


def test_spot_from_sphere_light_with_shaping_api(tmp_path):
    """UsdLux ShapingAPI on a SphereLight: a spot along the prim's -Z whose axis intensity is the
    unshaped sphere's (shaping multiplies radiance, it does not renormalise), cut off at
    shaping:cone:angle, faded per shaping:cone:softness."""
    stage, path = make_stage(tmp_path)
    a = _light(stage, UsdLux.SphereLight, "/L/spot", intensity=8.0, exposure=1.0, normalize=True)
    a.CreateRadiusAttr().Set(0.2)
    _shape(a, angle=30.0, softness=0.3, focus=2.0)
    UsdGeom.Xformable(a).AddTranslateOp().Set(Gf.Vec3d(1, 2, 3))
    UsdGeom.Xformable(a).AddRotateXOp().Set(90.0)  # -Z -> +Y
    b = _light(stage, UsdLux.SphereLight, "/L/hard", intensity=2.0)
    b.CreateRadiusAttr().Set(0.5)
    _shape(b, angle=45.0)
    c = _light(stage, UsdLux.SphereLight, "/L/default_cone", intensity=1.0, normalize=True)
    _shape(c)  # the spec's default cone angle, 90: "emission beyond it is guaranteed to be zero"
    d = _light(stage, UsdLux.SphereLight, "/L/open", intensity=1.0, normalize=True)
    _shape(d, angle=180.0)
    e = _light(stage, UsdLux.SphereLight, "/L/full_soft", intensity=1.0, normalize=True)
    _shape(e, angle=30.0, softness=1.0)
    stage.Save()
    sc = S.read_stage(path)
    s = _by_path(sc, "/L/spot").json
    assert s["type"] == "spot" and approx(s["position"], [1.0, 2.0, 3.0])
    assert approx(s["direction"], [0.0, 1.0, 0.0], abs_=1e-6)
    assert approx(s["intensity"], [16.0 / 4.0] * 3)  # normalize: I = intensity 2^exposure / 4
    assert s["radius"] == pytest.approx(0.2) and s["cone_half_angle_deg"] == pytest.approx(30.0)
    # the fades meet at their midpoint, 1/2 at 30 (1 - 0.3/2) = 25.5 degrees
    cos_out, cos_mid = math.cos(math.radians(30.0)), math.cos(math.radians(25.5))
    assert s["blend"] == pytest.approx(2.0 * (cos_mid - cos_out) / (1.0 - cos_out), rel=1e-6)
    assert s["blend"] == pytest.approx(0.5458, abs=1e-4)
    assert _by_path(sc, "/L/spot").detail["cone_fade_difference"] < 0.04
    assert any("/L/spot" in w and "focus" in w for w in sc.warnings), sc.warnings
    h = _by_path(sc, "/L/hard").json
    assert h["type"] == "spot" and h["blend"] == 0.0 and h["cone_half_angle_deg"] == pytest.approx(45.0)
    assert approx(h["intensity"], [2.0 * math.pi * 0.25] * 3)  # I = L pi r^2 without normalize
    assert approx(h["direction"], [0.0, 0.0, -1.0])
    assert _by_path(sc, "/L/default_cone").json["cone_half_angle_deg"] == pytest.approx(90.0)
    assert _by_path(sc, "/L/open").json["type"] == "point"
    assert _by_path(sc, "/L/full_soft").json["blend"] == 1.0
    assert any("/L/full_soft" in w and "softness" in w for w in sc.warnings), sc.warnings
    # Blender's convention: softness is Cycles' spot_blend
    assert S.read_stage(path, light_convention="blender").lights[0].json["blend"] == pytest.approx(0.3)


def test_rect_light_units_and_frame(tmp_path):
    """RectLight: width along local X, height along local Y, emits towards local -Z; with
    normalize the radiance is L' / world area (scale included)."""
    stage, path = make_stage(tmp_path)
    col = Gf.Vec3f(1.0, 0.5, 0.25)
    a = _light(stage, UsdLux.RectLight, "/L/norm", intensity=6.0, exposure=1.0, color=col, normalize=True)
    a.CreateWidthAttr().Set(2.0)
    a.CreateHeightAttr().Set(0.5)
    UsdGeom.Xformable(a).AddTranslateOp().Set(Gf.Vec3d(0, 0, 2))
    UsdGeom.Xformable(a).AddRotateZOp().Set(90.0)   # local X -> world +Y
    UsdGeom.Xformable(a).AddScaleOp().Set(Gf.Vec3f(1.5, 1.0, 1.0))
    b = _light(stage, UsdLux.RectLight, "/L/plain", intensity=3.0)
    b.CreateTextureFileAttr().Set(Sdf.AssetPath("panel.png"))
    UsdGeom.Xformable(b).AddRotateXOp().Set(-90.0)  # -Z -> -Y
    stage.Save()
    sc = S.read_stage(path)
    n = _by_path(sc, "/L/norm").json
    assert n["type"] == "rect" and approx(n["position"], [0.0, 0.0, 2.0])
    assert approx(n["normal"], [0.0, 0.0, -1.0], abs_=1e-6) and approx(n["tangent"], [0.0, 1.0, 0.0], abs_=1e-6)
    assert approx(n["size"], [3.0, 0.5])
    assert approx(n["radiance"], [12.0 * c / 1.5 for c in (1.0, 0.5, 0.25)])  # L = L' / (3 x 0.5 m^2)
    p = _by_path(sc, "/L/plain").json
    assert approx(p["size"], [1.0, 1.0]) and approx(p["radiance"], [3.0] * 3)  # spec defaults, no normalize
    assert approx(p["normal"], [0.0, -1.0, 0.0], abs_=1e-6)
    assert any("/L/plain" in w and "texture" in w for w in sc.warnings), sc.warnings


def test_disk_light_units(tmp_path):
    stage, path = make_stage(tmp_path, up="Y")
    a = _light(stage, UsdLux.DiskLight, "/L/norm", intensity=5.0, normalize=True)
    a.CreateRadiusAttr().Set(0.5)
    UsdGeom.Xformable(a).AddScaleOp().Set(Gf.Vec3f(2.0, 2.0, 1.0))
    b = _light(stage, UsdLux.DiskLight, "/L/ellipse", intensity=5.0)
    UsdGeom.Xformable(b).AddScaleOp().Set(Gf.Vec3f(2.0, 0.5, 1.0))
    c = _light(stage, UsdLux.DiskLight, "/L/shaped", intensity=5.0)
    _shape(c, angle=40.0)
    stage.Save()
    sc = S.read_stage(path)
    n = _by_path(sc, "/L/norm").json
    assert n["type"] == "disk" and n["radius"] == pytest.approx(1.0)
    assert approx(n["radiance"], [5.0 / math.pi] * 3)
    # Y-up: the light's -Z (towards the viewer of a Y-up stage) is volscatter's +Y
    assert approx(n["normal"], [0.0, 1.0, 0.0], abs_=1e-6)
    e = _by_path(sc, "/L/ellipse").json
    assert e["radius"] == pytest.approx(0.5) and approx(e["radiance"], [5.0] * 3)  # same area: 0.5 sqrt(2 x 0.5)
    assert any("/L/ellipse" in w and "same area" in w for w in sc.warnings), sc.warnings
    assert any("/L/shaped" in w and "ShapingAPI" in w for w in sc.warnings), sc.warnings


def test_pop_handles_sphere_and_dome_lights(tmp_path):
    stage, path = make_stage(tmp_path)
    _light(stage, UsdLux.DistantLight, "/L/sun", intensity=1.0)
    _light(stage, UsdLux.SphereLight, "/L/lamp", intensity=1.0)
    _light(stage, UsdLux.DomeLight, "/L/sky", intensity=1.0)
    stage.Save()
    sc = S.read_stage(path)
    # pop has radial grids and dome ordinates now: nothing is left out, by either solver
    assert [l.json["type"] for l in sc.lights] == ["distant", "point", "dome"]
    assert R.solver_warnings(sc, "pop") == []
    assert R.solver_warnings(sc, "reference") == []


# ------------------------------------------------------------------------------------------------
# world: transforms, metersPerUnit, upAxis

def test_volume_transform_and_meters_per_unit(tmp_path):
    stage, path = make_stage(tmp_path, mpu=0.01)
    vol = stage.GetPrimAtPath("/World/Smoke")
    UsdGeom.Xformable(vol).AddTranslateOp().Set(Gf.Vec3d(100, 200, 300))
    UsdGeom.Xformable(vol).AddScaleOp().Set(Gf.Vec3f(2, 2, 2))
    UsdGeom.Xformable(stage.GetPrimAtPath("/World/Cam")).AddTranslateOp().Set(Gf.Vec3d(0, -600, 0))
    l = _light(stage, UsdLux.SphereLight, "/L/lamp", intensity=4.0, normalize=True)
    UsdGeom.Xformable(l).AddTranslateOp().Set(Gf.Vec3d(0, 0, 500))
    l.CreateRadiusAttr().Set(10.0)
    stage.Save()
    sc = S.read_stage(path)
    assert sc.meters_per_unit == pytest.approx(0.01)
    m = sc.volumes[0].object_to_world
    assert m == pytest.approx([0.02, 0, 0, 1.0, 0, 0.02, 0, 2.0, 0, 0, 0.02, 3.0, 0, 0, 0, 1])
    assert approx(sc.camera.position, [0.0, -6.0, 0.0])
    lamp = _by_path(sc, "/L/lamp").json
    assert approx(lamp["position"], [0.0, 0.0, 5.0]) and lamp["radius"] == pytest.approx(0.1)
    assert approx(lamp["intensity"], [1.0] * 3)  # normalized: independent of size and units


def test_y_up_stage_is_turned_to_z_up(tmp_path):
    stage, path = make_stage(tmp_path, up="Y")
    UsdGeom.Xformable(stage.GetPrimAtPath("/World/Cam")).AddTranslateOp().Set(Gf.Vec3d(0, 0, 5))  # looks down -Z
    sun = _light(stage, UsdLux.DistantLight, "/L/sun", intensity=1.0)
    UsdGeom.Xformable(sun).AddRotateXOp().Set(-90.0)  # -Z -> -Y: straight down in a Y-up world
    stage.Save()
    sc = S.read_stage(path)
    assert sc.up_axis == "Y"
    assert approx(sc.camera.position, [0.0, -5.0, 0.0], abs_=1e-9)
    fwd = [sc.camera.look_at[i] - sc.camera.position[i] for i in range(3)]
    assert approx(fwd, [0.0, 1.0, 0.0], abs_=1e-9)
    assert approx(sc.camera.up, [0.0, 0.0, 1.0], abs_=1e-9)
    assert approx(_by_path(sc, "/L/sun").json["direction"], [0.0, 0.0, -1.0], abs_=1e-6)
    m = sc.volumes[0].object_to_world  # (x, y, z) -> (x, -z, y)
    assert m == pytest.approx([1, 0, 0, 0, 0, 0, -1, 0, 0, 1, 0, 0, 0, 0, 0, 1])


def test_volume_transform_at_time_code(tmp_path):
    stage, path = make_stage(tmp_path)
    op = UsdGeom.Xformable(stage.GetPrimAtPath("/World/Smoke")).AddTranslateOp()
    op.Set(Gf.Vec3d(0, 0, 0), 1.0)
    op.Set(Gf.Vec3d(10, 0, 0), 11.0)
    stage.SetStartTimeCode(1)
    stage.SetEndTimeCode(11)
    stage.Save()
    assert S.read_stage(path).volumes[0].object_to_world[3] == pytest.approx(0.0)  # start time code
    assert S.read_stage(path, time=6).volumes[0].object_to_world[3] == pytest.approx(5.0)


# ------------------------------------------------------------------------------------------------
# medium parameters, fields

def test_medium_from_attributes_options_defaults(tmp_path):
    stage, path = make_stage(tmp_path)
    prim = stage.GetPrimAtPath("/World/Smoke")
    prim.CreateAttribute("volscatter:densityScale", Sdf.ValueTypeNames.Float).Set(12.5)
    prim.CreateAttribute("volscatter:albedo", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(0.9, 0.8, 0.7))
    stage.Save()
    sc = S.read_stage(path, medium_defaults={"density_scale": 3.0, "albedo": 0.5, "g": 0.4})
    m = sc.volumes[0].medium
    assert m.density_scale == [12.5] * 3 and m.albedo == pytest.approx([0.9, 0.8, 0.7]) and m.g == pytest.approx(0.4)
    assert m.source == {"density_scale": "attribute volscatter:densityScale", "albedo": "attribute volscatter:albedo",
                        "g": "option"}
    prim.CreateAttribute("volscatter:g", Sdf.ValueTypeNames.Float).Set(1.5)
    stage.Save()
    with pytest.raises(VolscatterError, match="g = 1.5"):
        S.read_stage(path)


def test_field_selection_and_bad_fields(tmp_path):
    stage, path = make_stage(tmp_path, vdb=TWO_GRIDS)
    f = UsdVol.OpenVDBAsset(stage.GetPrimAtPath("/World/Smoke/density"))
    f.CreateFieldIndexAttr().Set(0)
    stage.Save()
    assert S.read_stage(path).volumes[0].field_name == "density"
    f.GetFieldIndexAttr().Set(1)
    stage.Save()
    with pytest.raises(VolscatterError, match="fieldIndex 1 out of range"):
        S.read_stage(path)
    f.GetFieldIndexAttr().Clear()
    f.GetFieldNameAttr().Set("velocity")
    stage.Save()
    with pytest.raises(VolscatterError, match="float grid"):
        S.read_stage(path)
    f.GetFieldNameAttr().Set("temperature")
    stage.Save()
    with pytest.raises(VolscatterError, match=r"'temperature' is not a grid .*density \(Tree_float_5_4_3\), velocity"):
        S.read_stage(path)


def test_time_sampled_file_path(tmp_path):
    stage, path = make_stage(tmp_path)
    shutil.copy(MINI, tmp_path / "vol" / "e.vdb")
    fp = UsdVol.OpenVDBAsset(stage.GetPrimAtPath("/World/Smoke/density")).GetFilePathAttr()
    fp.Clear()
    fp.Set(Sdf.AssetPath("./vol/d.vdb"), 1.0)
    fp.Set(Sdf.AssetPath("./vol/e.vdb"), 2.0)
    stage.SetStartTimeCode(1)
    stage.SetEndTimeCode(2)
    stage.Save()
    assert Path(S.read_stage(path, time=1).volumes[0].vdb_path).name == "d.vdb"
    assert Path(S.read_stage(path, time=2).volumes[0].vdb_path).name == "e.vdb"


# ------------------------------------------------------------------------------------------------
# bad input

def test_missing_vdb(tmp_path):
    stage, path = make_stage(tmp_path)
    UsdVol.OpenVDBAsset(stage.GetPrimAtPath("/World/Smoke/density")).GetFilePathAttr().Set(Sdf.AssetPath("./gone.vdb"))
    stage.Save()
    with pytest.raises(VolscatterError, match=r"gone.vdb' not found"):
        S.read_stage(path)


def test_not_a_vdb(tmp_path):
    stage, path = make_stage(tmp_path)
    (tmp_path / "vol" / "d.vdb").write_bytes(b"this is not a vdb file")
    with pytest.raises(VolscatterError, match="not an OpenVDB file"):
        S.read_stage(path)


def test_no_volume_no_camera(tmp_path):
    stage, path = make_stage(tmp_path, with_volume=False, with_camera=False)
    stage.Save()
    sc = S.read_stage(path)
    assert sc.volumes == [] and sc.camera is None
    with pytest.raises(VolscatterError, match="no UsdVolVolume"):
        sc.scene_json()


def test_malformed_and_missing_stage(tmp_path):
    bad = tmp_path / "bad.usda"
    bad.write_text("#usda 1.0\ndef Xform \"x\" {\n  float a = \n")
    with pytest.raises(VolscatterError, match="cannot open stage"):
        S.read_stage(bad)
    with pytest.raises(VolscatterError, match="stage not found"):
        S.read_stage(tmp_path / "nope.usda")


def test_camera_path_errors(tmp_path):
    stage, path = make_stage(tmp_path)
    stage.Save()
    with pytest.raises(VolscatterError, match=r"camera /No/Such does not exist .*cameras: /World/Cam"):
        S.read_stage(path, camera="/No/Such")
    with pytest.raises(VolscatterError, match="not a Camera"):
        S.read_stage(path, camera="/World/Smoke")
    assert S.read_stage(path, camera="/World/Cam").camera.fov_deg == pytest.approx(
        math.degrees(2 * math.atan(36.0 / 100.0)))


# ------------------------------------------------------------------------------------------------
# CLI helpers

def test_frame_patterns():
    assert R.frame_path("out.####.exr", 7) == "out.0007.exr"
    assert R.frame_path("out_{frame}.exr", 12.0) == "out_12.exr"
    assert R.frame_path("out_{frame:03d}.exr", 5) == "out_005.exr"
    assert C.parse_frames("1-3") == [1.0, 2.0, 3.0]
    assert C.parse_frames("-2--1") == [-2.0, -1.0]
    assert C.parse_frames("0-10:5") == [0.0, 5.0, 10.0]
    with pytest.raises(VolscatterError):
        C.parse_frames("3-1")
    with pytest.raises(VolscatterError):
        C.parse_frames("abc")


def _fake_exr_header(path, w, h):
    """An OpenEXR header with just a data window (exr_size reads no more; no pixels are read)."""
    import struct
    attr = b"dataWindow\0box2i\0" + struct.pack("<i", 16) + struct.pack("<4i", 0, 0, w - 1, h - 1)
    path.write_bytes(b"\x76\x2f\x31\x01" + struct.pack("<I", 2) + attr + b"\0")


def test_dome_texture_orientation(tmp_path):
    stage, path = make_stage(tmp_path)
    _fake_exr_header(tmp_path / "sky.exr", 8, 4)
    _fake_exr_header(tmp_path / "flat.exr", 1, 1)
    assert S.exr_size(tmp_path / "sky.exr") == (8, 4)
    ok = UsdLux.DomeLight.Define(stage, "/L/aligned")
    ok.CreateTextureFileAttr().Set(Sdf.AssetPath("./sky.exr"))
    UsdGeom.Xformable(ok).AddRotateXYZOp().Set(Gf.Vec3f(90, 0, 90))  # USD lat-long -> volscatter's
    bad = UsdLux.DomeLight.Define(stage, "/L/unrotated")
    bad.CreateTextureFileAttr().Set(Sdf.AssetPath("./sky.exr"))
    bad.CreateIntensityAttr().Set(2.0)
    bad.CreateColorAttr().Set(Gf.Vec3f(1.0, 0.5, 1.0))
    flat = UsdLux.DomeLight.Define(stage, "/L/flat")
    flat.CreateTextureFileAttr().Set(Sdf.AssetPath("./flat.exr"))
    stage.Save()
    sc = S.read_stage(path)
    orient = [w for w in sc.warnings if "orientation" in w]
    assert len(orient) == 1 and "/L/unrotated" in orient[0]
    j = _by_path(sc, "/L/unrotated").json
    assert j["intensity"] == pytest.approx(2.0) and j["color"] == pytest.approx([1.0, 0.5, 1.0])
    assert Path(j["texture"]) == (tmp_path / "sky.exr").resolve()
    # Blender's convention: its unrotated dome holds a map in Blender's (= volscatter's) layout
    assert not [w for w in S.read_stage(path, light_convention="blender").warnings if "orientation" in w]
    UsdLux.DomeLight.Define(stage, "/L/missing").CreateTextureFileAttr().Set(Sdf.AssetPath("./nope.exr"))
    stage.Save()
    with pytest.raises(VolscatterError, match="nope.exr' not found"):
        S.read_stage(path)


def test_medium_from_bound_material(tmp_path):
    from pxr import UsdShade
    stage, path = make_stage(tmp_path)
    mat = UsdShade.Material.Define(stage, "/Looks/Smoke")
    sh = UsdShade.Shader.Define(stage, "/Looks/Smoke/vdf")
    sh.CreateIdAttr("ND_anisotropic_vdf")
    sh.CreateInput("absorption", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(1.0, 2.0, 3.0))
    sh.CreateInput("scattering", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(3.0, 2.0, 1.0))
    sh.CreateInput("anisotropy", Sdf.ValueTypeNames.Float).Set(0.3)
    mat.CreateOutput("volume", Sdf.ValueTypeNames.Token).ConnectToSource(sh.CreateOutput("out", Sdf.ValueTypeNames.Token))
    vol = stage.GetPrimAtPath("/World/Smoke")
    UsdShade.MaterialBindingAPI.Apply(vol).Bind(mat)
    vol.CreateAttribute("volscatter:g", Sdf.ValueTypeNames.Float).Set(-0.2)  # attributes win
    stage.Save()
    m = S.read_stage(path, medium_defaults={"density_scale": 9.0}).volumes[0].medium
    assert m.density_scale == pytest.approx([4.0, 4.0, 4.0])
    assert m.albedo == pytest.approx([0.75, 0.5, 0.25])
    assert m.g == pytest.approx(-0.2)
    assert m.source == {"density_scale": "material /Looks/Smoke", "albedo": "material /Looks/Smoke",
                        "g": "attribute volscatter:g"}
    # a material volscatter cannot read is reported, and the options apply
    sh.GetPrim().RemoveProperty("inputs:scattering")
    stage.Save()
    sc = S.read_stage(path, medium_defaults={"density_scale": 9.0})
    assert sc.volumes[0].medium.density_scale == [9.0] * 3
    assert any("/Looks/Smoke is not a network volscatter reads" in w for w in sc.warnings)


def test_camera_settings_volscatter_cannot_honour(tmp_path):
    stage, path = make_stage(tmp_path)
    cam = UsdGeom.Camera(stage.GetPrimAtPath("/World/Cam"))
    UsdGeom.Xformable(cam).AddTranslateOp().Set(Gf.Vec3d(0, -6, 0))
    UsdGeom.Xformable(cam).AddRotateXOp().Set(90.0)
    cam.CreateClippingRangeAttr().Set(Gf.Vec2f(0.1, 5.0))  # the fog reaches ~100 m away
    UsdGeom.Boundable(stage.GetPrimAtPath("/World/Smoke")).CreateExtentAttr().Set(
        [Gf.Vec3f(0, 0, 0), Gf.Vec3f(103, 1, 1)])
    cam.CreateHorizontalApertureOffsetAttr().Set(2.0)
    stage.Save()
    sc = S.read_stage(path)
    assert any("clipping range" in w and "/World/Smoke" in w for w in sc.warnings), sc.warnings
    assert any("horizontalApertureOffset" in w for w in sc.warnings)
    cam.CreateProjectionAttr().Set("orthographic")
    stage.Save()
    with pytest.raises(VolscatterError, match="orthographic"):
        S.read_stage(path)


def test_invisible_volume_and_light_left_out(tmp_path):
    stage, path = make_stage(tmp_path)
    sun = _light(stage, UsdLux.DistantLight, "/L/sun", intensity=1.0)
    UsdGeom.Imageable(sun).MakeInvisible()
    UsdGeom.Imageable(stage.GetPrimAtPath("/World/Smoke")).MakeInvisible()
    stage.Save()
    sc = S.read_stage(path)
    assert sc.volumes == [] and sc.lights == []
    assert any("/World/Smoke is invisible" in w for w in sc.warnings)
    assert any("/L/sun is invisible" in w for w in sc.warnings)


def test_vec3_vdb_writer_against_openvdb(tmp_path):
    """The bake's vec3s writer: OpenVDB reads every voxel back, at the right world position."""
    import subprocess
    np = pytest.importorskip("numpy")
    sys_py = "/usr/bin/python3"
    if not Path(sys_py).exists() or subprocess.run([sys_py, "-c", "import pyopenvdb"]).returncode != 0:
        pytest.skip("pyopenvdb not importable by /usr/bin/python3 (apt-get install python3-openvdb)")
    from volscatter._native import vdb_info, write_vdb  # the library's writer (vs_vdb_write_grids)
    rng = np.random.default_rng(5)
    a = rng.random((9, 140, 130, 3)).astype(np.float32)  # crosses internal-node borders at 128
    a[a < 0.6] = 0.0
    m = [0.0, -0.05, 0.0, 1.0, 0.05, 0.0, 0.0, -2.0, 0.0, 0.0, 0.1, 0.5, 0, 0, 0, 1]  # rotated, scaled, moved
    write_vdb(tmp_path / "v.vdb", [("scatter", a)], m)
    n = vdb_info(tmp_path / "v.vdb", stats=True)["grids"][0]["active_voxels"]  # as the library reads it back
    assert n == int((a != 0).any(axis=3).sum())
    np.save(tmp_path / "v.npy", a)
    code = ("import pyopenvdb as v, numpy as np, sys, json\n"
            "g = v.read(sys.argv[1], 'scatter'); a = np.load(sys.argv[2])\n"
            "out = np.zeros((a.shape[2], a.shape[1], a.shape[0], 3), np.float32)\n"
            "g.copyToArray(out, ijk=(0, 0, 0))\n"
            "print(json.dumps([g.valueTypeName, g.activeVoxelCount(), float(np.abs(out.transpose(2, 1, 0, 3) - a).max()),"
            " list(g.transform.indexToWorld((3, 4, 5)))]))")
    r = subprocess.run([sys_py, "-c", code, str(tmp_path / "v.vdb"), str(tmp_path / "v.npy")], capture_output=True,
                       text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    import json
    vt, count, err, p = json.loads(r.stdout)
    assert vt == "vec3s" and count == n and err == 0.0
    assert p == pytest.approx([1.0 - 0.05 * 4, -2.0 + 0.05 * 3, 0.5 + 0.1 * 5], abs=1e-9)


# ------------------------------------------------------------------------------------------------
# bad attributes (issue 22): each is a VolscatterError naming the prim and the attribute, never a
# traceback or a JSON parse error about a document the user never wrote

def _author(stage, prim_path, name, type_name, value):
    """Authors in the layer (Sdf), as a hand-edited .usda would: the Usd API refuses a value whose
    type differs from the schema's, a file does not."""
    spec = stage.GetRootLayer().GetPrimAtPath(prim_path)
    if name in spec.properties:
        spec.RemoveProperty(spec.properties[name])
    Sdf.AttributeSpec(spec, name, type_name).default = value


@pytest.mark.parametrize("prim_path,name,type_name,value,needle", [
    ("/World/Cam", "horizontalAperture", "float", float("nan"), "not finite"),
    ("/World/Cam", "focalLength", "float", float("inf"), "not finite"),
    ("/World/Smoke", "volscatter:densityScale", "float", float("nan"), "not finite"),
    ("/World/Smoke", "volscatter:albedo", "color3f", (0.5, float("nan"), 0.5), "not finite"),
    ("/World/Smoke", "volscatter:g", "string", "forward", "a number is expected"),
    ("/World/Sun", "inputs:intensity", "float", float("nan"), "not finite"),
    ("/World/Sun", "inputs:color", "string", "red", "a number is expected"),
    ("/World/Sun", "inputs:angle", "string", "wide", "a number is expected"),
    ("/World/Sky", "inputs:texture:file", "int", 7, "an asset path is expected"),
    ("/World/Smoke/density", "filePath", "int", 3, "an asset path is expected"),
    ("/World/Smoke/density", "fieldIndex", "string", "first", "a number is expected"),
])
def test_bad_attributes_name_the_prim_and_attribute(tmp_path, prim_path, name, type_name, value, needle):
    stage, path = make_stage(tmp_path)
    UsdLux.DistantLight.Define(stage, "/World/Sun")
    UsdLux.DomeLight.Define(stage, "/World/Sky")
    _author(stage, prim_path, name, getattr(Sdf.ValueTypeNames, type_name[0].upper() + type_name[1:]), value)
    stage.Save()
    with pytest.raises(VolscatterError) as e:
        S.read_stage(path).scene_json()
    assert f"{prim_path}: attribute {name}" in str(e.value) and needle in str(e.value), str(e.value)


def test_finite_attributes_that_overflow_are_named_by_prim(tmp_path):
    """intensity x 2^exposure beyond float range: named, not a traceback (OverflowError)."""
    stage, path = make_stage(tmp_path)
    sun = UsdLux.DistantLight.Define(stage, "/World/Sun")
    sun.CreateExposureAttr().Set(5000.0)
    stage.Save()
    with pytest.raises(VolscatterError, match=r"/World/Sun.*overflows"):
        S.read_stage(path).scene_json()
    sun.CreateExposureAttr().Set(200.0)
    sun.CreateIntensityAttr().Set(3e38)
    stage.Save()
    with pytest.raises(VolscatterError, match=r"/World/Sun: the computed irradiance .* is not finite"):
        S.read_stage(path).scene_json()
