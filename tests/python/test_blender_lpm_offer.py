"""The add-on's offer of Light Propagation Maps streamed for large volumes (lpm_offer.py, issue
19), through headless bpy like test_blender_addon.py (whose install fixtures it uses; skipped
with the reason when bpy or the library is missing).

The large volume is tests/python/fixtures/sparse_1024.vdb: written by our library (the Rust test
plugin/src/ffi/lpm_estimate_tests.rs), two leaves at opposite corners of a 1024^3 index box, 11
KiB on disk, 4 GiB dense: the offer's numbers come from the file's topology, never its voxels.
"""

import ctypes
import os
import shutil
import sys

import pytest

from test_blender_addon import MODULE, bpy, bs, fresh, installed, zip_path, _run, _smoke_domain, _tiny  # noqa: F401 (fixtures)

FIXTURE = os.path.join(os.path.dirname(os.path.abspath(__file__)), "fixtures", "sparse_1024.vdb")


def _mod(name):
    return sys.modules[MODULE + "." + name]


class _Layout:
    """Records what the panel draws (labels and operators)."""

    use_property_split = False
    active = True
    enabled = True

    def __init__(self, seen):
        self.seen = seen

    def column(self, **kw):
        return _Layout(self.seen)

    row = column

    def separator(self, **kw):
        pass

    def label(self, text="", **kw):
        self.seen["labels"].append(text)

    def prop(self, data, name, **kw):
        assert name in data.bl_rna.properties, name
        self.seen["props"].append(name)

    def operator(self, idname, **kw):
        cat, name = idname.split(".")
        assert hasattr(getattr(bpy.ops, cat), name), idname
        self.seen["ops"].append(idname)


def _draw(ob):
    from types import SimpleNamespace
    seen = {"labels": [], "props": [], "ops": []}
    _mod("panel").VOLSCATTER_PT_volume.draw(SimpleNamespace(layout=_Layout(seen)), SimpleNamespace(object=ob, scene=bpy.context.scene))
    return seen


def _small_file_volume(folder):
    """A 12^3 noise volume saved to a VDB and read back as a file-backed Volume."""
    gen = bs.noise_volume(name="Gen", res=12)
    path = str(folder / "small.vdb")
    gen.evaluated_get(bpy.context.evaluated_depsgraph_get()).data.grids.save(filepath=path)
    bpy.data.objects.remove(gen)
    return bs.file_volume("Small", path)


IDENTITY = [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]


def direct_estimate(ob, settings_of=None):
    """The library's estimate for what Compute Scattering runs on `ob` once "Use Light
    Propagation Maps (Streamed)" was pressed on it (the operator run here, then the settings
    Compute reads: `solver_settings()` of the object that owns them, default `ob`)."""
    assert _run(bpy.ops.volscatter.use_lpm_streamed, ob) == {'FINISHED'}
    s = (settings_of or ob).volscatter
    return _mod("native").lpm_estimate(FIXTURE, None, IDENTITY, s.max_resolution, s.solver_settings())


def test_sparse_1024_vdb_gets_the_offer_with_the_librarys_numbers(fresh):
    assert os.path.getsize(FIXTURE) < 16 << 10, "a sparse file"
    offer_mod, native = _mod("lpm_offer"), _mod("native")
    ob = bs.file_volume("Big", FIXTURE)
    s = ob.volscatter
    got = offer_mod.offer(ob, bpy.context)
    assert got is not None, "a 4 GiB (dense) volume gets the offer"
    est, proposed = got
    assert est["voxels"] == [1024] * 3 and est["dense_bytes"] == 4 << 30
    # The medium read at twice lpm's grid (default preset's grid_resolution), the budget a
    # quarter of the library's (at most 1 GiB).
    grid = proposed["grid_resolution"]
    assert proposed["max_resolution"] == 2 * grid and est["medium_dims"] == [2 * grid] * 3
    assert est["medium_bytes"] == 4 * (2 * grid) ** 3
    assert proposed["lpm_memory_budget_mib"] == min(1024, native.lib().vs_memory_budget() >> 22)
    assert est["grid_dims"] == [grid] * 3, "a cube: grid_resolution cells a side"
    # The numbers are the library's, for the settings the operator sets and Compute then runs.
    assert direct_estimate(ob) == est
    assert s.solver == "lpm" and s.lpm_out_of_core
    assert 0 < est["out_of_core_bytes"] <= proposed["lpm_memory_budget_mib"] << 20
    assert est["in_memory_bytes"] > est["out_of_core_bytes"] > 0
    seen = _draw(ob)
    assert "volscatter.use_lpm_streamed" in seen["ops"]
    text = " | ".join(seen["labels"])
    assert "1024x1024x1024 voxels, 4.0 GiB dense" in text, text
    assert "Streamed: " in text and "MiB budget" in text, text


def test_offer_estimates_the_quality_presets_settings(fresh):
    """The estimate is for the settings Compute runs under each Quality (the preset's
    `directions` included: draft 4, final 36), not for lpm's defaults."""
    offer_mod = _mod("lpm_offer")
    ob = bs.file_volume("Big", FIXTURE)
    s = ob.volscatter
    seen = {}
    for quality in ("DRAFT", "PREVIEW", "FINAL", "CUSTOM"):
        s.solver, s.quality, s.lpm_out_of_core = "auto", quality, False
        est, proposed = offer_mod.offer(ob, bpy.context)
        assert direct_estimate(ob) == est, quality
        if quality != "CUSTOM":
            assert s.solver_settings()["directions"] == {"DRAFT": 4, "PREVIEW": 25, "FINAL": 36}[quality]
        seen[quality] = est
    # The directions change what lpm holds (so the comparison above can fail): final's 36 per
    # face against preview's 25 on the same grid would be more; the grids differ too.
    assert seen["FINAL"]["in_memory_bytes"] > seen["PREVIEW"]["in_memory_bytes"] > seen["DRAFT"]["in_memory_bytes"]
    # At equal grids, only the directions differ: Custom at final's grid (40) against Final.
    s.solver, s.quality, s.lpm_out_of_core = "lpm", "CUSTOM", False
    s.grid_resolution = 40
    est, _ = offer_mod.offer(ob, bpy.context)
    assert est["grid_dims"] == seen["FINAL"]["grid_dims"]
    assert est["in_memory_bytes"] < seen["FINAL"]["in_memory_bytes"], "lpm's default 25 directions hold less than 36"


def test_offer_follows_a_result_volume_and_a_smoke_domain_to_their_source(fresh):
    """The offer describes what Compute would solve (operators.source_of's lookup) with the
    settings it reads: asked on a result volume, its source; on a smoke domain, its cache."""
    offer_mod = _mod("lpm_offer")
    big = bs.file_volume("Big", FIXTURE)
    result = _small_file_volume(fresh)
    result[_mod("operators").RESULT_TAG] = big.name
    got = offer_mod.offer(result, bpy.context)
    assert got is not None and got[0]["voxels"] == [1024] * 3, "the source's file, not the result's"
    assert "volscatter.use_lpm_streamed" in _draw(result)["ops"]
    assert direct_estimate(result, settings_of=big) == got[0]
    assert big.volscatter.solver == "lpm" and big.volscatter.lpm_out_of_core, "the operator sets the source's settings"
    assert not result.volscatter.lpm_out_of_core

    # A smoke domain before Compute made its cache volume: the cache file of the frame.
    dom = _smoke_domain(str(fresh / "cache"), ())
    shutil.copy(FIXTURE, str(fresh / "cache" / "data" / "fluid_data_0003.vdb"))
    bpy.context.scene.frame_set(3)
    n_objects = len(bpy.data.objects)
    got = offer_mod.offer(dom, bpy.context)
    assert got is not None and got[0]["voxels"] == [1024] * 3
    assert len(bpy.data.objects) == n_objects, "read only: no cache volume made while drawing"
    assert direct_estimate(dom) == got[0]
    assert dom.volscatter.lpm_out_of_core


def test_small_volume_gets_no_offer(fresh):
    ob = _small_file_volume(fresh)
    assert _mod("lpm_offer").source_file(ob) is not None, "file-backed: the offer was considered"
    assert _mod("lpm_offer").offer(ob, bpy.context) is None
    assert "volscatter.use_lpm_streamed" not in _draw(ob)["ops"]
    # A generated volume (no file) is never offered.
    gen = bs.noise_volume(name="Gen2", res=4)
    assert _mod("lpm_offer").offer(gen, bpy.context) is None


def test_operator_sets_lpm_streamed_idempotently_and_compute_succeeds(fresh):
    ob = _small_file_volume(fresh)
    bs.principled_material(ob)
    bs.sun()
    bs.camera()
    _tiny(ob, fresh / "out", solver="pop")
    s = ob.volscatter

    def state():
        return (s.solver, s.quality, s.grid_resolution, s.lpm_out_of_core, s.lpm_memory_budget_mib, s.max_resolution)

    assert _run(bpy.ops.volscatter.use_lpm_streamed, ob) == {'FINISHED'}
    first = state()
    assert _run(bpy.ops.volscatter.use_lpm_streamed, ob) == {'FINISHED'}
    assert state() == first, "running it twice changes nothing"
    assert first[0] == "lpm" and first[3] and first[5] == 2 * first[2]
    settings = s.solver_settings()
    assert settings["out_of_core"] is True and settings["first_order"] == "boundary"
    assert settings["memory_budget"] == s.lpm_memory_budget_mib << 20
    doc, _, _ = _mod("scene_export").export(bpy.context, ob, str(fresh / "x"), 1, {"name": "lpm"},
                                           max_resolution=s.max_resolution)
    assert doc["medium"]["max_resolution"] == s.max_resolution
    assert _run(bpy.ops.volscatter.compute_scattering, ob) == {'FINISHED'}
    res = bpy.data.objects.get("Small_scattering")
    assert res is not None and os.path.isfile(res.data.filepath)


def test_estimate_refuses_null_and_garbage_paths(fresh, tmp_path):
    native = _mod("native")
    junk = tmp_path / "junk.vdb"
    junk.write_bytes(b"not an OpenVDB file at all")
    with pytest.raises(native.VolscatterError) as e:
        native.lpm_estimate(str(junk))
    assert e.value.status == 7 and "junk.vdb" in str(e.value), "FORMAT, naming the file"
    with pytest.raises(native.VolscatterError) as e:
        native.lpm_estimate(str(tmp_path / "missing.vdb"))
    assert e.value.status == 6, "IO"
    with pytest.raises(native.VolscatterError) as e:
        native.lpm_estimate(FIXTURE, settings={"grid_res": 3})
    assert e.value.status == 5 and "grid_res" in str(e.value), "INVALID_SCENE, naming the setting"
    out = native.LpmEstimate()
    with native.Scene() as sc:
        assert native.lib().vs_scene_lpm_estimate(sc.ptr, None, None, None, 0, None, ctypes.byref(out)) == 1, "NULL path"
        assert native.lib().vs_scene_lpm_estimate(sc.ptr, FIXTURE.encode(), None, None, 0, None, None) == 1, "NULL out"
    assert native.lib().vs_scene_lpm_estimate(None, FIXTURE.encode(), None, None, 0, None, ctypes.byref(out)) == 1, "NULL scene"
