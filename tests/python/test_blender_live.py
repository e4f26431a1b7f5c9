"""Live mode (issue 38): the add-on's update step driven from a script, through headless bpy
like test_blender_addon.py (whose install fixtures it uses; skipped with the reason when bpy or
the library is missing). Headless Blender runs no timers: the test calls `live.step` /
`live.wait`, what Blender's timer calls in the UI.
"""

import os
import sys
import threading

import pytest

from test_blender_addon import (MODULE, SCATTER_GRIDS, _run, _tiny, bpy, bs, fresh,  # noqa: F401
                                installed, zip_path)


def _live():
    return sys.modules[MODULE + ".live"]


def _scene(folder, g=0.0):
    """A file-backed smoke under a sun, pop (deterministic) at Custom quality."""
    gen = bs.noise_volume(name="Gen", res=10)
    dg = bpy.context.evaluated_depsgraph_get()
    path = os.path.join(str(folder), "smoke.vdb")
    gen.evaluated_get(dg).data.grids.save(filepath=path)
    bpy.data.objects.remove(gen)
    ob = bs.file_volume("Smoke", path)
    bs.principled_material(ob, density=3.0, anisotropy=g)
    bs.sun(strength=3.0)
    bs.camera(width=16, height=12)
    _tiny(ob, folder / "out", solver="pop")
    ob.volscatter.iterations = 200
    return ob


def _live_threads():
    return [t for t in threading.enumerate() if t.name.startswith("volscatter live") and t.is_alive()]


def _sample(ob):
    pts = bs.lattice((-0.8, -0.8, -0.8), (0.8, 0.8, 0.8), 4)
    s = bs.sample_grids(ob, list(SCATTER_GRIDS), pts)
    return [v for n in SCATTER_GRIDS for v in s[n]]


def _result():
    return bpy.data.objects["Smoke_scattering"]


def _live_files(folder):
    return sorted(f for f in os.listdir(str(folder)) if f.endswith(".vdb"))


@pytest.fixture
def live_off():
    yield
    _live().stop_all()


def test_live_is_off_by_default(fresh, live_off):
    ob = _scene(fresh)
    assert ob.volscatter.live is False
    bpy.data.objects["Sun"].rotation_euler.x += 0.3
    bpy.context.view_layer.update()
    assert _live().step() is False and "Smoke_scattering" not in bpy.data.objects


def test_moved_light_gives_the_one_off_solve(fresh, live_off):
    """Live on solves at once (a draft first: no preview timed yet, then the preview); moving
    the sun solves again, updating the same result volume in place, and the draft's and the
    first preview's files are gone. The live result equals Compute Scattering of the moved
    scene (same solver, settings and seed; a session gives what a one-off solve gives): to
    1e-4 relative, float rounding."""
    live = _live()
    ob = _scene(fresh)
    ob.volscatter.live = True
    live.wait()
    res = _result()
    first = bpy.path.abspath(res.data.filepath)
    assert os.path.isfile(first) and ob.hide_render  # Hide Original
    assert live.status(ob).startswith("Preview on the"), live.status(ob)
    bpy.data.objects["Sun"].rotation_euler.x += 0.5
    bpy.context.view_layer.update()
    live.wait()
    assert _result() == res, "a new result object instead of the one updated in place"
    moved = bpy.path.abspath(res.data.filepath)
    assert moved != first and not os.path.exists(first)
    assert _live_files(fresh / "out") == [os.path.basename(moved)]
    got = _sample(res)
    ob.volscatter.live = False
    assert _run(bpy.ops.volscatter.compute_scattering, ob) == {'FINISHED'}
    want = _sample(_result())
    assert max(want) > 0.0
    assert got == pytest.approx(want, rel=1e-4, abs=1e-6 * max(want))
    assert not _live_threads()


def test_ten_quick_moves_leave_one_finished_solve(fresh, live_off):
    """Ten moves in a row, each seen by a step, cancel the solves they overtake: at the end one
    result, one file (the last scene's preview), no worker thread."""
    live = _live()
    ob = _scene(fresh)
    ob.volscatter.live = True
    live.wait()
    sun = bpy.data.objects["Sun"]
    for i in range(10):
        sun.rotation_euler.x += 0.05
        bpy.context.view_layer.update()
        live.step()
    live.wait()
    assert not _live_threads()
    assert [o.name for o in bpy.data.objects if o.get("volscatter_source") == "Smoke"] == ["Smoke_scattering"]
    assert _live_files(fresh / "out") == [os.path.basename(bpy.path.abspath(_result().data.filepath))]
    assert live.status(ob).startswith("Preview"), live.status(ob)
    # the result is the last scene's: one more step finds nothing to do
    assert live.step() is False


def test_camera_restarts_only_an_anisotropic_medium(fresh, live_off):
    """The scattering towards the viewer depends on the camera only where g != 0."""
    live = _live()
    import addon_utils
    for g, expect in ((0.0, False), (0.6, True)):
        bs.reset()
        addon_utils.enable(MODULE, default_set=True)
        folder = fresh / ("g%s" % g)
        folder.mkdir()
        ob = _scene(folder, g=g)
        ob.volscatter.live = True
        live.wait()
        bpy.data.objects["Camera"].location.x += 0.5
        bpy.context.view_layer.update()
        assert live._live["Smoke"].pending is expect, g
        live.wait()
        live.stop_all()


def test_frame_change_restarts_and_live_off_stops(fresh, live_off):
    """A new frame solves again; turning Live off cancels, closes the sessions and leaves no
    thread."""
    live = _live()
    ob = _scene(fresh)
    ob.volscatter.live = True
    live.wait()
    state = live._live["Smoke"]
    n = len(state.applied)
    bpy.context.scene.frame_set(2)
    assert state.pending
    live.step()
    assert state.job is not None or len(state.applied) > n
    ob.volscatter.live = False
    assert "Smoke" not in live._live and not state.sessions
    live.wait()
    assert not _live_threads()
