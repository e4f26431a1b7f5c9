"""The files a result reads: names unique to each run, self-contained VDBs, what is missing,
and which files no .blend uses any more.

A result file is `<object>_<run>_<frame>.vdb` (run: 8 hex digits, new for every Compute
Scattering or live update), holding the scattering grids and a byte-for-byte copy of the
density grid it was solved with, so it renders right without its source. Nothing here deletes
a file that the open .blend or a given .blend reads: recomputing leaves the earlier files (a
saved file or the undo stack may still read them); "Clean up Unused Results" removes the rest.
"""

import glob
import os
import re
import uuid

import bpy

from . import native

#: Custom property on a result object: the name of the source object it was computed for.
RESULT_TAG = "volscatter_source"

#: What the add-on writes into an output folder: results, and the inputs it generates for the
#: solver (Geometry Nodes volumes) that a crash mid-run can leave behind.
_RESULT_FILE = re.compile(r"^.+_[0-9a-f]{8}_\d{4,}\.vdb$")
_INPUT_FILE = re.compile(r"^.+_input_\d{4,}\.vdb$")


def new_run_id():
    """8 hex digits, new for every run: no two runs write the same file name."""
    return uuid.uuid4().hex[:8]


def result_path(folder, name, run, number):
    return os.path.join(folder, "%s_%s_%04d.vdb" % (bpy.path.clean_name(name), run, number))


def is_ours(filename):
    """Whether a file name is one the add-on writes (a result or a generated input)."""
    return bool(_RESULT_FILE.match(filename) or _INPUT_FILE.match(filename))


def write_self_contained(path, result, object_to_world, density_vdb, density_grid):
    """Writes `result`'s scattering grids (scattering_r/_g/_b) in the space of the object whose
    matrix is `object_to_world` (16 floats, row-major), with grid `density_grid` of
    `density_vdb` copied in byte for byte (it keeps its own transform, the source file's,
    which is that object's space too). Atomic (the library writes a temporary file and renames
    it). Returns False when the density could not be copied (the file then has the scattering
    only), True otherwise."""
    import numpy as np
    rgb = result.rgb()
    i2w = np.asarray(result.index_to_world(), dtype=np.float64).reshape(4, 4)
    o2w = np.asarray(object_to_world, dtype=np.float64).reshape(4, 4)
    i2l = np.linalg.solve(o2w, i2w).reshape(-1).tolist()
    grids = [("scattering_" + c, rgb[..., i]) for i, c in enumerate("rgb")]
    try:
        native.write_vdb(path, grids, i2l, copies=[(density_grid, density_vdb, density_grid)])
        return True
    except native.VolscatterError as e:
        if e.status not in (native.STATUS_FORMAT, native.STATUS_UNSUPPORTED):
            raise
    native.write_vdb(path, grids, i2l)
    return False


# ---------------------------------------------------------------------------------------------
# what a volume reads, and whether it is there


def volume_files(vol, library=None):
    """The absolute paths of the files volume data `vol` can read: its file, or for a
    sequence every file numbered like it in its folder."""
    if not vol.filepath:
        return []
    path = os.path.normpath(bpy.path.abspath(vol.filepath, library=library or vol.library))
    if not getattr(vol, "is_sequence", False):
        return [path]
    folder, base = os.path.split(path)
    m = re.match(r"^(.*?)(\d+)(\.vdb)$", base)
    if not m:
        return [path]
    return [path] + sorted(p for p in glob.glob(os.path.join(glob.escape(folder), glob.escape(m.group(1)) + "*" + m.group(3)))
                           if re.fullmatch(re.escape(m.group(1)) + r"\d+" + re.escape(m.group(3)), os.path.basename(p)))


def current_file(ob):
    """The file volume object `ob` reads at the current frame (Blender resolves sequences), or
    None when it reads no file."""
    vol = ob.data
    if not getattr(vol, "filepath", ""):
        return None
    path = getattr(vol.grids, "frame_filepath", "") or vol.filepath
    return os.path.normpath(bpy.path.abspath(path, library=vol.library))


def missing_file(ob):
    """The file volume object `ob` should read at the current frame when it is not there,
    else None."""
    if ob is None or ob.type != 'VOLUME':
        return None
    path = current_file(ob)
    return path if path is not None and not os.path.isfile(path) else None


def results_of(source):
    """The result objects computed for `source`."""
    return [o for o in bpy.data.objects if o.type == 'VOLUME' and o.get(RESULT_TAG) == source.name]


def missing_warnings(ob):
    """Warnings for the panel and render time about `ob` (a source or a result): a result file
    or a source file that is not there."""
    out = []
    src_name = ob.get(RESULT_TAG)
    results = [ob] if src_name else results_of(ob)
    for r in results:
        path = missing_file(r)
        if path:
            out.append("Result '%s' is missing its file %s: compute again" % (r.name, path))
    source = bpy.data.objects.get(src_name) if src_name else ob
    path = missing_file(source) if source is not None else None
    if path:
        out.append("Source '%s' is missing its file %s%s" % (source.name, path,
                   "; its result keeps its own density" if results else ""))
    return out


def render_warnings(scene):
    """The missing-file warnings of every result a render of `scene` shows."""
    out = []
    for ob in scene.objects:
        if ob.type == 'VOLUME' and ob.get(RESULT_TAG) and not ob.hide_render:
            path = missing_file(ob)
            if path:
                out.append("volscatter: result '%s' is missing its file %s, so it renders nothing; compute "
                           "again" % (ob.name, path))
    return out


# ---------------------------------------------------------------------------------------------
# clean up


def _paths_in_open_file():
    out = set()
    for vol in bpy.data.volumes:
        out.update(volume_files(vol))
    return out


def paths_in_blend(blend):
    """The files the volumes of the saved .blend `blend` read, without opening it: its volumes
    are linked in, read and unlinked."""
    before = set(bpy.data.libraries)
    out = set()
    src = os.path.normpath(os.path.abspath(blend))
    copy = None
    if bpy.data.filepath and src == os.path.normpath(bpy.data.filepath):
        # Blender links nothing from the open file: its saved state is read from a copy in
        # the same folder (so that its relative paths resolve the same), removed after.
        import shutil
        copy = os.path.join(os.path.dirname(src), ".%s.volscatter-scan.blend" % new_run_id())
        shutil.copyfile(src, copy)
        src = copy
    try:
        with bpy.data.libraries.load(src, link=True) as (data_from, data_to):
            data_to.volumes = list(data_from.volumes)
        for vol in data_to.volumes:
            if vol is not None:
                out.update(volume_files(vol, library=vol.library))
    finally:
        for lib in set(bpy.data.libraries) - before:
            bpy.data.libraries.remove(lib)
        if copy is not None:
            try:
                os.remove(copy)
            except OSError:
                pass
    return out


def blends_beside(folder):
    """The .blend files (and Blender's .blend1 ... backups) in `folder`."""
    try:
        names = os.listdir(folder)
    except OSError:
        return []
    return sorted(os.path.join(folder, f) for f in names
                  if re.search(r"\.blend\d*$", f) and "volscatter-scan" not in f)


def unused_files(folders, blends):
    """The files the add-on wrote in `folders` that neither the open .blend nor any of `blends`
    reads, sorted."""
    used = _paths_in_open_file()
    for b in blends:
        used |= paths_in_blend(b)
    out = []
    for folder in folders:
        try:
            names = os.listdir(folder)
        except OSError:
            continue
        for f in names:
            p = os.path.normpath(os.path.join(folder, f))
            if is_ours(f) and p not in used:
                out.append(p)
    return sorted(set(out))
