"""EEVEE + volscatter against Cycles' multiple scattering, in CI (issue 20).

EEVEE has single scattering only. volscatter's Compute Scattering replaces a volume by one that
emits the multiple-scattered light S with the same extinction, so EEVEE renders what Cycles
renders with many volume bounces. Three scenes (tests/python/eevee_scenes.py): a smoke under a
sun and a sky, a dense cloud (optical depth ~30 through its centre, albedo 0.95), a smoke lit by
a point light; each rendered by EEVEE alone and by EEVEE with the add-on's result, both with the
EEVEE settings the add-on recommends (install/blender/volscatter_blender/eevee.py), against a
converged Cycles render with 64 (the cloud: 256) volume bounces stored in
tests/python/fixtures/eevee/ (scripts/make_eevee_fixtures.py; each .json beside it records its
samples and its own noise, 1-3% relative RMSE). Metrics: relative RMSE of the premultiplied RGB
over the image (film transparent: only the volume counts) and the flux (sum of RGB) ratio.

Skipped, with the reason, when bpy, the library or an EEVEE (OpenGL through EGL: Debian
libegl-mesa0 + libgl1-mesa-dri) is not available.
"""

import ctypes
import json
import os
import subprocess
import sys
import textwrap

import pytest

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(HERE))
LIB = os.environ.get("VOLSCATTER_LIB") or os.path.join(REPO, "target", "release", "libvolscatter.so")

if not os.path.isfile(LIB):
    pytest.skip("libvolscatter not built (%s); run cargo build --release -p volscatter --lib or set VOLSCATTER_LIB"
                % LIB, allow_module_level=True)
try:
    ctypes.CDLL(LIB).vs_result_write_grid
except (OSError, AttributeError) as e:
    pytest.skip("%s is not a usable libvolscatter with the C ABI (%s); rebuild it" % (LIB, e), allow_module_level=True)

bpy = pytest.importorskip("bpy", reason="bpy (pip install bpy==5.0.1, Python 3.11) is not importable")

import numpy as np  # noqa: E402

import eevee_scenes as es  # noqa: E402


def _eevee_probe():
    """None when EEVEE renders here, else why not. In a child process: without an OpenGL
    context bpy can abort the whole process instead of raising."""
    code = textwrap.dedent("""
        import bpy
        bpy.ops.wm.read_factory_settings(use_empty=True)
        sc = bpy.context.scene
        sc.render.engine = %r
        cam = bpy.data.objects.new("c", bpy.data.cameras.new("c"))
        sc.collection.objects.link(cam)
        sc.camera = cam
        sc.render.resolution_x = sc.render.resolution_y = 4
        bpy.ops.render.render()
        print("EEVEE-OK")
    """ % es.ENGINE_EEVEE)
    try:
        r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    except subprocess.TimeoutExpired:
        return "a 4x4 EEVEE render did not finish in 300 s"
    if r.returncode == 0 and "EEVEE-OK" in r.stdout:
        return None
    tail = " | ".join((r.stdout + r.stderr).strip().splitlines()[-3:])
    return ("EEVEE cannot render here (exit %d: %s); it needs OpenGL through EGL (Debian: libegl-mesa0 "
            "libgl1-mesa-dri)" % (r.returncode, tail))


@pytest.fixture(scope="module")
def addon():
    """The add-on from the source tree (install/blender), registered, loading $VOLSCATTER_LIB."""
    why = _eevee_probe()
    if why:
        pytest.skip(why)
    os.environ["VOLSCATTER_LIB"] = LIB
    # An installed copy (test_blender_addon.py's extension) would own the same class names.
    import addon_utils
    for mod in [m for m in list(bpy.context.preferences.addons.keys()) if m.endswith("volscatter_blender")]:
        addon_utils.disable(mod, default_set=True)
    sys.path.insert(0, os.path.join(REPO, "install", "blender"))
    sys.path.insert(0, os.path.join(REPO, "install"))
    import build_extension
    build_extension.copy_binding()  # the add-on's native.py, from usd/volscatter/_native.py
    import volscatter_blender
    volscatter_blender.register()
    yield sys.modules["volscatter_blender.eevee"]
    es.bs.reset()
    volscatter_blender.unregister()


def _reference(name):
    ref = es.load_reference(name)
    with open(os.path.join(es.FIXTURES, name + ".json")) as f:
        meta = json.load(f)
    assert ref.shape == (es.HEIGHT, es.WIDTH, 4) and np.isfinite(ref).all()
    return ref, meta


#: Per scene: (solver, Custom settings or None for the Preview preset). pop (principal ordinates,
#: ~3 s here) for the sun and sky and the cloud; the reference path tracer (~15 s) for the point
#: light, where pop at Preview is 13% dark (BENCHMARKS.md "EEVEE": error 0.19, flux 0.87).
SOLVERS = {"smoke_sun_sky": ("pop", None), "dense_cloud": ("pop", None), "smoke_point": ("reference", None)}

#: EEVEE + volscatter must be at least this many times closer (relative RMSE) to Cycles than
#: EEVEE alone. Measured (BENCHMARKS.md "EEVEE"): 0.783 / 0.119 = 6.6x, 0.783 / 0.150 = 5.2x,
#: 0.291 / 0.091 = 3.2x (EEVEE alone under the point light has no volumetric shadows, its default:
#: the unattenuated light makes up in flux, 0.83, for the missing orders). About half of each.
FACTOR = {"smoke_sun_sky": 3.0, "dense_cloud": 3.0, "smoke_point": 2.0}
#: |flux ratio - 1| allowed for EEVEE + volscatter against Cycles. Measured: 0.904 (pop is dark
#: where light arrives after many orders; issue 20's 5% of the grid handed to hosts is part of
#: it), 1.047, 0.969. Tolerance: the measured gap plus 5 points for the fixtures' noise (2-4%)
#: and the solver's seed.
FLUX_TOL = {"smoke_sun_sky": 0.15, "dense_cloud": 0.10, "smoke_point": 0.10}


@pytest.mark.parametrize("name", es.SCENES)
def test_eevee_with_volscatter_is_closer_to_cycles(addon, tmp_path, name):
    ref, meta = _reference(name)
    ob = es.build(name)
    sc = bpy.context.scene
    assert bpy.ops.volscatter.eevee_settings() == {'CANCELLED'}  # no result yet: nothing to set
    solver, settings = SOLVERS[name]
    res = es.compute_scattering(ob, solver, tmp_path, **(settings or {}))
    e_default = _default_froxels(addon, sc, ref, tmp_path) if name == "smoke_sun_sky" else None
    # 8 -> 2 on these 80x60 frames, where a voxel of the result covers ~0.3 px
    assert [c[:3] for c in addon.recommend(sc)] == [("volumetric_tile_size", '8', '2')]
    _panel_lines(addon, sc, res)
    assert bpy.ops.volscatter.eevee_settings() == {'FINISHED'}
    assert sc.eevee.volumetric_tile_size == '2'
    assert addon.recommend(sc) == []  # applied: nothing left to recommend
    with_vs = es.render_eevee(str(tmp_path / "eevee_volscatter.exr"))
    # EEVEE alone: the source volume with its own material, the same EEVEE settings
    res.hide_render = True
    ob.hide_render = False
    alone = es.render_eevee(str(tmp_path / "eevee_alone.exr"))
    e_vs, e_alone = es.rel_rmse(with_vs, ref), es.rel_rmse(alone, ref)
    f_vs, f_alone = es.flux_ratio(with_vs, ref), es.flux_ratio(alone, ref)
    print("%s: EEVEE alone %.3f (flux %.3f), EEVEE + volscatter %.3f (flux %.3f), Cycles noise %.3f"
          % (name, e_alone, f_alone, e_vs, f_vs, meta["noise_rel_rmse"]))
    # the same extinction as Cycles' medium: the coverage (alpha) agrees whatever lights it
    assert np.abs(with_vs[..., 3] - ref[..., 3]).mean() < 0.02
    assert e_vs * FACTOR[name] < e_alone, "EEVEE + volscatter %.3f, EEVEE alone %.3f" % (e_vs, e_alone)
    assert abs(f_vs - 1.0) < FLUX_TOL[name], "flux %.3f of Cycles'" % f_vs
    # EEVEE alone misses the multiple scattering: its flux is farther off
    assert abs(f_alone - 1.0) > abs(f_vs - 1.0)
    if e_default is not None:
        assert e_vs * 1.5 < e_default, "the recommended froxels %.3f, EEVEE's default %.3f" % (e_vs, e_default)


def _panel_lines(addon, sc, res):
    """The EEVEE sub-panel, drawn into a recording layout: shown for EEVEE only, it lists the
    recommendation and offers the operator."""
    from types import SimpleNamespace
    drawn = []

    class Layout:
        def column(self, **kw):
            return self

        def label(self, text="", **kw):
            drawn.append(text)

        def operator(self, idname, **kw):
            drawn.append(idname)

    ctx = SimpleNamespace(object=res, scene=sc)
    sc.render.engine = 'CYCLES'
    assert not addon.VOLSCATTER_PT_eevee.poll(ctx)
    sc.render.engine = es.ENGINE_EEVEE
    assert addon.VOLSCATTER_PT_eevee.poll(ctx)
    addon.VOLSCATTER_PT_eevee.draw(SimpleNamespace(layout=Layout()), ctx)
    assert drawn == ["volumetric_tile_size: 2 (now 8)", "volscatter.eevee_settings"], drawn


def _default_froxels(addon, sc, ref, tmp_path):
    """The error of the result rendered with EEVEE's default froxels (8 px tiles), which blur
    it: the recommended tile (2 px here) must be measurably closer to Cycles (measured 0.27 ->
    0.12; asserted by the caller: 1.5x). Also checks that a camera clip range cutting through
    the result (EEVEE's volume range when Custom Range is off; measured: a clip end of 5 m
    leaves 5% of the flux) is extended by the recommendation."""
    assert sc.eevee.volumetric_tile_size == '8'
    default = es.render_eevee(str(tmp_path / "default_tile.exr"))
    e_default = es.rel_rmse(default, ref)
    print("EEVEE's default tile 8: %.3f" % e_default)
    clip_end = sc.camera.data.clip_end
    sc.camera.data.clip_end = 5.0  # the camera is 6 m from the smoke's centre
    changes = dict((c[0], c[2]) for c in addon.recommend(sc))
    assert set(changes) == {"volumetric_tile_size", "camera.clip_end"}, changes
    assert changes["camera.clip_end"] > 6.0 + 1.5  # the smoke's far corner: ~7.7 m
    sc.eevee.use_volume_custom_range, sc.eevee.volumetric_end = True, 5.0
    assert addon.recommend(sc)[-1][:3] == ("volumetric_end", 5.0, changes["camera.clip_end"])
    sc.eevee.use_volume_custom_range = False
    sc.camera.data.clip_end = clip_end
    return e_default
