"""What the add-on's panel, menus and status line say (issue 38, "honest UI"), through headless
bpy like test_blender_addon.py (whose install fixtures it uses; skipped with the reason when
bpy or the library is missing): the Device line says what will run, tooltips are one sentence,
the Automatic pick is said once, a cap names its cause, progress moves through the stages.
"""

import sys

from test_blender_addon import (MODULE, _UIContext, _drive, _modal_harness, _run, _tiny, bpy, bs, fresh,  # noqa: F401
                                installed, zip_path)


def _mod(name):
    return sys.modules[MODULE + "." + name]


def _scene(res=8):
    ob = bs.noise_volume(res=res)
    bs.principled_material(ob, density=3.0)
    bs.sun(strength=3.0)
    bs.camera(width=12, height=9)
    return ob


def test_device_line_says_what_will_run(fresh):
    """Automatic: what it picked and where it ran, once computed (it used to say that `auto`
    "has no GPU backend" while running solvers that have one); a solver without a GPU backend
    runs on the CPU; one with a backend under Device Auto, on a hardware GPU if one works. No
    lower-cased menu names ("Device Gpu")."""
    ops, native = _mod("operators"), _mod("native")
    ob = _scene()
    s = ob.volscatter
    assert s.solver == "auto"
    assert ops.device_line(s) == "Auto -> a solver picked for the scene when you compute"
    s.quality, s.output_dir, s.device = 'DRAFT', str(fresh), 'AUTO'
    assert _run(bpy.ops.volscatter.compute_scattering, ob) == {'FINISHED'}
    picked = s.last_choice.split(":")[0][len("auto picked "):]
    assert ops.device_line(s) == "Auto -> %s on the %s (last run)" % (picked, s.last_device)
    assert s.last_device in ("CPU", "GPU")
    entries = native.solvers()["solvers"]
    without = next(e for e in entries if not e["gpu"] and e["name"] != "auto")
    with_gpu = next(e for e in entries if e["gpu"])
    s.solver = without["name"]
    assert ops.device_line(s) == "%s on the CPU (no GPU backend)" % without["label"]
    s.solver = with_gpu["name"]
    assert ops.device_line(s) == "%s on a hardware GPU if one works, else the CPU" % with_gpu["label"]
    s.device = 'GPU'
    assert "Gpu" not in ops.device_line(s) and "GPU" in ops.device_line(s)
    # Device Auto with a solver that has no GPU backend is not a warning (it promises no GPU)
    assert ops.device_note(without["name"], 'AUTO') is None and ops.device_note("auto", 'GPU') is None


def test_auto_pick_is_said_once(fresh):
    """The report used to repeat the pick ("auto picked vpl draft: vpl draft: the fastest ...")."""
    H = _modal_harness()
    ob = _scene()
    ob.volscatter.quality, ob.volscatter.output_dir = 'DRAFT', str(fresh)
    op, ctx = H(), _UIContext(ob)
    op.reports = []
    assert _drive(op, ctx) == {'FINISHED'}, op.reports
    picks = [m for k, m in op.reports if "auto picked" in m]
    assert len(picks) == 1, op.reports
    pick = picks[0][len("volscatter: auto picked "):].split(":")[0]
    assert picks[0].count(pick) == 1, picks[0]


def test_tooltips_are_one_sentence(fresh):
    """Menu tooltips from the registry's help strings: one sentence each, capitalised (they used
    to be paragraphs with benchmark notes)."""
    props = _mod("properties")
    ob = bs.noise_volume(res=4)
    items = props._solver_items(ob.volscatter, bpy.context) + props._quality_items(ob.volscatter, bpy.context)
    for ident, label, desc, number in items:
        assert desc and desc[0] == desc[0].upper(), (ident, desc)
        assert ". " not in desc and not desc.endswith("."), (ident, desc)
    for item in props.VolscatterSettings.bl_rna.properties["device"].enum_items:
        assert ". " not in item.description and "(" not in item.description, item.description


def test_cap_names_max_resolution_when_it_is_the_cause(fresh):
    """A grid capped by Max Resolution says so (it used to blame the source's voxels)."""
    panel = _mod("panel")
    ob = bs.standard_scene(res=24, points=False)
    _tiny(ob, fresh)
    s = ob.volscatter
    s.grid_resolution, s.max_resolution = 20, 8
    assert _run(bpy.ops.volscatter.compute_scattering, ob) == {'FINISHED'}
    assert 0 < s.last_resolution < 20
    note = panel.cap_note(s)
    assert note and "Max Resolution" in note and "source" not in note, note


def test_progress_moves_through_the_stages(fresh):
    """The status line names each stage (capitalised) with its fraction and the seconds
    running; over a solve it changes (it used to sit on "photons 0%" until done)."""
    H = _modal_harness()
    ob = bs.standard_scene(res=8)
    _tiny(ob, fresh)
    ob.volscatter.samples = 400  # long enough for several timer ticks
    op, ctx = H(), _UIContext(ob)
    op.reports = []
    assert _drive(op, ctx) == {'FINISHED'}, op.reports
    shown = [t for t in ctx.workspace.texts if t]
    assert len(set(shown)) >= 2, shown
    assert all("%" in t and " s)" in t for t in shown), shown
    assert any(t.split(": ", 2)[-1][:1].isupper() for t in shown), shown
