"""Mantaflow smoke domains as volscatter sources.

A smoke domain is a mesh object with a Fluid modifier; its baked cache is a folder of VDB files
(`<cache>/data/fluid_data_####.vdb`, one per frame, numbered by scene frame). Selecting the
domain does what a user would do by hand: a Volume object reads that sequence (as *File >
Import > OpenVDB* of every file does, so the grids sit where the cache's own transform puts
them) and gets the domain's material (an imported cache has none). That volume is made once,
hidden (the domain keeps rendering itself), named `<domain>_cache`, and refreshed on every
run so that a re-bake or a moved cache folder is followed.
"""

import os
import re

import bpy

from .scene_export import ExportError

#: Custom property on the cache volume naming its domain.
DOMAIN_TAG = "volscatter_domain"

_FILE = re.compile(r"fluid_data_(\d+)\.vdb$")


def gas_domain(ob):
    """The domain settings when `ob` is a Mantaflow gas (smoke, fire) domain, else None."""
    if ob is None or ob.type != 'MESH':
        return None
    for m in ob.modifiers:
        if m.type == 'FLUID' and m.fluid_type == 'DOMAIN' and m.domain_settings.domain_type == 'GAS':
            return m.domain_settings
    return None


def cache_sequence(domain_ob):
    """-> (data folder, [(frame, file name)] sorted by frame) of the domain's baked cache; an
    ExportError saying what to do when there is none."""
    ds = gas_domain(domain_ob)
    folder = os.path.normpath(os.path.join(bpy.path.abspath(ds.cache_directory, library=domain_ob.library), "data"))
    if ds.cache_data_format != 'OPENVDB':
        raise ExportError("smoke domain '%s' caches in %s; volscatter reads OpenVDB caches (Cache > Format "
                          "Volumes: OpenVDB, then bake again)" % (domain_ob.name, ds.cache_data_format))
    try:
        names = os.listdir(folder)
    except OSError:
        names = []
    files = sorted((int(m.group(1)), n) for n in names for m in [_FILE.match(n)] if m)
    if not files:
        raise ExportError("smoke domain '%s' has no baked cache in %s (no fluid_data_####.vdb): bake the "
                          "simulation first (Physics > Fluid > Cache > Bake Data)" % (domain_ob.name, folder))
    return folder, files


def find_cache_volume(domain_ob):
    """The Volume object `cache_volume` made for the domain, or None (read only)."""
    return next((o for o in bpy.data.objects if o.type == 'VOLUME' and o.get(DOMAIN_TAG) == domain_ob.name), None)


def cache_file(domain_ob, frame):
    """The cache file the domain's cache volume reads at `frame` (read only, nothing made): as
    `cache_volume` sets the sequence, frame f reads fluid_data_f.vdb, clipped to the first and
    last file; an ExportError when there is no cache, None when that frame's file is missing."""
    folder, files = cache_sequence(domain_ob)
    f = min(max(frame, files[0][0]), files[-1][0])
    name = dict(files).get(f)
    return os.path.join(folder, name) if name else None


def cache_volume(domain_ob, context):
    """The Volume object reading the domain's cache sequence, with the domain's material:
    made on first use, updated after. Frame f reads fluid_data_<f>.vdb."""
    folder, files = cache_sequence(domain_ob)
    first, last = files[0][0], files[-1][0]
    ob = find_cache_volume(domain_ob)
    if ob is None:
        vol = bpy.data.volumes.new(domain_ob.name + "_cache")
        ob = bpy.data.objects.new(domain_ob.name + "_cache", vol)
        ob[DOMAIN_TAG] = domain_ob.name
        for c in list(domain_ob.users_collection) or [context.scene.collection]:
            c.objects.link(ob)
        # The domain renders the smoke itself; this volume only feeds volscatter (hidden in the
        # view layer, not disabled, so that the depsgraph still evaluates it).
        ob.hide_render = True
        if ob.name in context.view_layer.objects:
            ob.hide_set(True)
    vol = ob.data
    path = os.path.join(folder, files[0][1])
    vol.filepath = bpy.path.relpath(path) if bpy.data.filepath else path
    vol.is_sequence = len(files) > 1
    if vol.is_sequence:
        # file number = frame - frame_start + 1 + frame_offset == frame
        vol.frame_start = first
        vol.frame_duration = last - first + 1
        vol.frame_offset = first - 1
        vol.sequence_mode = 'CLIP'
    mat = domain_ob.active_material
    if mat is None:
        raise ExportError("smoke domain '%s' has no material (volscatter reads density, colour and anisotropy "
                          "from it: give it a Principled Volume)" % domain_ob.name)
    if list(vol.materials) != [mat]:
        vol.materials.clear()
        vol.materials.append(mat)
    return ob
