"""Blender scene -> volscatter scene JSON (format 1, docs/scene-format.md).

Everything here reads Blender data and changes nothing in the .blend: the only side effect is
writing a generated volume (Geometry Nodes, Mantaflow in memory) to a VDB file in the given
folder. What cannot be interpreted raises `ExportError` with a message fit for the UI; what is
left out (unsupported lights, ignored shader inputs) is collected in `warnings`.

Conventions (measured with Cycles, /work/shared/notes/blender-conventions.md):
- sun: `strength` is irradiance (W/m^2) perpendicular to the beam; `angle` its diameter;
- point of power P: intensity P / (4 pi) W/sr, radius = `shadow_soft_size`, its interior lit
  (Cycles lights points inside the sphere with its surface's radiance from every direction);
- spot of power P: the same axis intensity P / (4 pi) W/sr as a point of P watts (the cone
  masks, it does not concentrate: a Cycles 5.0.1 render of a visible spot of radius r shows
  radiance P / (4 pi^2 r^2) for any spot_size); cone half-angle spot_size / 2; `spot_blend` is
  the core's `blend` (Cycles: smoothstep in the cosine over the outer blend fraction);
- area of power P and world area A (object scale included): radiance P / (pi A) W/m^2/sr from
  its local -Z face (a visible 1 m^2 square of 10 W renders 3.183 in Cycles 5.0.1, and the same
  holds for rectangle, disk and ellipse with their own areas); an ellipse becomes the disk of
  the same area (same power, same radiance);
- world background colour C, strength s: dome radiance C * s;
- Volume Scatter: sigma_s = Color * Density; Volume Absorption: sigma_a = (1 - Color) * Density;
- Principled Volume (Cycles svm_node_principled_volume): with D = Density * grid,
  sigma_s = Color * D, sigma_t = (Color + (1 - Color) * (1 - sqrt(Absorption Color))) * D.
"""

import math
import os

import bpy

from . import emission_export, native

FORMAT = 1


class ExportError(Exception):
    """The scene cannot be exported; the message is shown to the user as is."""


# ---------------------------------------------------------------------------------------------
# Medium: the VDB file and its grid


def _abs(path, lib=None):
    return os.path.normpath(bpy.path.abspath(path, library=lib))


def _has_generating_modifiers(obj):
    return any(m.show_render for m in getattr(obj, "modifiers", []))


def volume_vdb(obj, depsgraph, out_dir, frame, grid_hint=None):
    """Returns (vdb_path, grid_names, generated) for a Volume object at the current frame.

    A volume backed by a file (and not changed by modifiers) is used in place; for image
    sequences the frame's file is resolved by Blender. Volumes made or changed by modifiers
    (Geometry Nodes, a Mantaflow cache loaded by a modifier) are saved from the evaluated
    data to `out_dir` first."""
    if obj is None or obj.type != 'VOLUME':
        raise ExportError("'%s' is not a Volume object (select the volume to compute scattering for)"
                          % (obj.name if obj else "nothing"))
    vol = obj.data
    eval_obj = obj.evaluated_get(depsgraph)
    eval_vol = eval_obj.data
    grids = eval_vol.grids
    try:
        grids.load()
    except Exception:
        pass
    names = [g.name for g in grids]
    if not _has_generating_modifiers(obj) and vol.filepath:
        path = grids.frame_filepath if hasattr(grids, "frame_filepath") and grids.frame_filepath else vol.filepath
        path = _abs(path, vol.library)
        if not os.path.isfile(path):
            raise ExportError("Volume '%s': its VDB file %s does not exist (frame %d)" % (obj.name, path, frame))
        if not names:
            err = getattr(grids, "error_message", "") or "no grids"
            raise ExportError("Volume '%s': Blender cannot read %s: %s" % (obj.name, path, err))
        return path, names, False
    if not names:
        if vol.filepath:
            err = getattr(grids, "error_message", "") or "no grids"
            raise ExportError("Volume '%s' has no grids after its modifiers (%s)" % (obj.name, err))
        raise ExportError("Volume '%s' has no VDB file and no grids (load a .vdb, bake the simulation, "
                          "or generate the volume with Geometry Nodes)" % obj.name)
    os.makedirs(out_dir, exist_ok=True)
    path = os.path.join(out_dir, "%s_input_%04d.vdb" % (bpy.path.clean_name(obj.name), frame))
    # saved beside under a temporary name, then renamed: a failed save leaves no partial file
    tmp = os.path.join(out_dir, ".%s.%d.tmp.vdb" % (os.path.basename(path), os.getpid()))
    try:
        ok = grids.save(filepath=tmp)
        if ok is not False and os.path.isfile(tmp):
            os.replace(tmp, path)
    except Exception as e:  # RuntimeError with Blender's message
        raise ExportError("Volume '%s': cannot write its generated grids to %s: %s" % (obj.name, path, e))
    finally:
        _remove(tmp)
    if ok is False or not os.path.isfile(path):
        raise ExportError("Volume '%s': writing its generated grids to %s failed" % (obj.name, path))
    return path, names, True


# ---------------------------------------------------------------------------------------------
# Material


def _volume_output_link(mat):
    if mat is None:
        raise ExportError("the volume has no material (volscatter needs a Principled Volume or "
                          "Volume Scatter/Absorption shader to know density, colour and anisotropy)")
    if not mat.node_tree:
        raise ExportError("material '%s' does not use nodes" % mat.name)
    outputs = [n for n in mat.node_tree.nodes if n.type == 'OUTPUT_MATERIAL']
    active = [n for n in outputs if n.is_active_output] or outputs
    for n in active:
        sock = n.inputs.get("Volume")
        if sock is not None and sock.is_linked:
            return sock.links[0].from_node
    raise ExportError("material '%s' has nothing connected to the Material Output's Volume input" % mat.name)


def _rgb(sock):
    v = sock.default_value
    try:
        return [float(v[0]), float(v[1]), float(v[2])]
    except TypeError:
        return [float(v)] * 3


def _unlinked(sock, what, mat):
    if sock.is_linked:
        raise ExportError("material '%s': %s is driven by a node (%s); volscatter reads only constant "
                          "values there" % (mat.name, what, sock.links[0].from_node.name))
    return sock


def _density_source(sock, mat):
    """A Density socket -> (grid attribute name, scale). Accepts Attribute(name).Fac (or
    Volume Info Density), optionally times a constant through Math Multiply."""
    if not sock.is_linked:
        raise ExportError("material '%s': %s Density is a constant, not a grid (connect an Attribute "
                          "node with the grid name, e.g. 'density')" % (mat.name, sock.node.name))
    return _grid_expr(sock.links[0], mat, 0)


def _grid_expr(link, mat, depth):
    node = link.from_node
    if depth > 8:
        raise ExportError("material '%s': density expression too deep" % mat.name)
    out = link.from_socket.identifier
    if node.type == 'ATTRIBUTE' and out in ("Fac", "Color"):
        if getattr(node, "attribute_type", "GEOMETRY") not in ("GEOMETRY",):
            raise ExportError("material '%s': attribute node '%s' must be of type Geometry" % (mat.name, node.name))
        return node.attribute_name, 1.0
    if node.type == 'VOLUME_INFO' and out == "Density":
        return "density", 1.0
    if node.type == 'MATH' and node.operation == 'MULTIPLY':
        a, b = node.inputs[0], node.inputs[1]
        if a.is_linked and not b.is_linked:
            name, s = _grid_expr(a.links[0], mat, depth + 1)
            return name, s * float(b.default_value)
        if b.is_linked and not a.is_linked:
            name, s = _grid_expr(b.links[0], mat, depth + 1)
            return name, s * float(a.default_value)
    if node.type == 'REROUTE':
        return _grid_expr(node.inputs[0].links[0], mat, depth + 1) if node.inputs[0].is_linked else (None, 0.0)
    raise ExportError("material '%s': cannot interpret the density from node '%s' (supported: Attribute "
                      "or Volume Info Density, optionally through Math Multiply by a constant)"
                      % (mat.name, node.name))


def _collect_shaders(node, mat, out, depth=0):
    if depth > 8:
        raise ExportError("material '%s': shader tree too deep" % mat.name)
    if node.type == 'ADD_SHADER':
        for s in node.inputs:
            if s.is_linked:
                _collect_shaders(s.links[0].from_node, mat, out, depth + 1)
        return
    if node.type == 'REROUTE' and node.inputs[0].is_linked:
        _collect_shaders(node.inputs[0].links[0].from_node, mat, out, depth + 1)
        return
    if node.type in ('PRINCIPLED_VOLUME', 'VOLUME_SCATTER', 'VOLUME_ABSORPTION'):
        out.append(node)
        return
    raise ExportError("material '%s': cannot interpret shader node '%s' (%s); volscatter understands "
                      "Principled Volume, or Volume Scatter and/or Volume Absorption joined by Add Shader"
                      % (mat.name, node.name, node.bl_label))


def material_params(mat, grid_names, warnings):
    """-> dict(grid=..., density_scale=[r,g,b], albedo=[r,g,b], g=float)."""
    shaders = []
    _collect_shaders(_volume_output_link(mat), mat, shaders)
    principled = [n for n in shaders if n.type == 'PRINCIPLED_VOLUME']
    if principled and len(shaders) > 1:
        raise ExportError("material '%s': a Principled Volume mixed with other volume shaders is not supported"
                          % mat.name)
    if principled:
        return _principled(principled[0], mat, grid_names, warnings)
    scatter = [n for n in shaders if n.type == 'VOLUME_SCATTER']
    absorb = [n for n in shaders if n.type == 'VOLUME_ABSORPTION']
    if len(scatter) > 1 or len(absorb) > 1:
        raise ExportError("material '%s': more than one Volume Scatter or Volume Absorption node" % mat.name)
    sig_s = [0.0, 0.0, 0.0]
    sig_a = [0.0, 0.0, 0.0]
    grid = None
    g = 0.0
    for node in scatter + absorb:
        name, scale = _density_source(node.inputs["Density"], mat)
        if grid is not None and name != grid:
            raise ExportError("material '%s': scatter and absorption read different grids ('%s', '%s')"
                              % (mat.name, grid, name))
        grid = name
        d = scale
        col = _rgb(_unlinked(node.inputs["Color"], "%s Color" % node.name, mat))
        if node.type == 'VOLUME_SCATTER':
            phase = getattr(node, "phase", 'HENYEY_GREENSTEIN')
            if phase != 'HENYEY_GREENSTEIN':
                raise ExportError("material '%s': Volume Scatter phase '%s' is not supported (use Henyey-Greenstein)"
                                  % (mat.name, phase))
            g = float(_unlinked(node.inputs["Anisotropy"], "Anisotropy", mat).default_value)
            for c in range(3):
                sig_s[c] += max(col[c], 0.0) * d
        else:
            for c in range(3):
                sig_a[c] += max(1.0 - col[c], 0.0) * d
    return _finish(mat, grid, sig_s, sig_a, g, grid_names)


def _principled(node, mat, grid_names, warnings):
    inp = node.inputs
    col = _rgb(_unlinked(inp["Color"], "Principled Volume Color", mat))
    dens = float(_unlinked(inp["Density"], "Principled Volume Density", mat).default_value)
    absc = _rgb(_unlinked(inp["Absorption Color"], "Principled Volume Absorption Color", mat))
    g = float(_unlinked(inp["Anisotropy"], "Principled Volume Anisotropy", mat).default_value)
    grid = inp["Density Attribute"].default_value if "Density Attribute" in inp else "density"
    if "Color Attribute" in inp:
        ca = inp["Color Attribute"].default_value
        if ca and ca in grid_names:
            raise ExportError("material '%s': the colour comes from grid '%s' per voxel; volscatter needs one "
                              "colour (clear Color Attribute)" % (mat.name, ca))
    emission = emission_export.principled_emission(node, mat, grid_names, warnings, _grid_expr)
    sig_s = [max(c, 0.0) * dens for c in col]
    sig_t = []
    for c in range(3):
        a = max(1.0 - col[c], 0.0) * max(1.0 - math.sqrt(max(absc[c], 0.0)), 0.0)
        sig_t.append((max(col[c], 0.0) + a) * dens)
    sig_a = [sig_t[c] - sig_s[c] for c in range(3)]
    params = _finish(mat, grid, sig_s, sig_a, g, grid_names)
    if emission:
        params["emission"] = emission
    return params


def _finish(mat, grid, sig_s, sig_a, g, grid_names):
    if not grid:
        raise ExportError("material '%s': no density grid attribute named" % mat.name)
    if grid not in grid_names:
        raise ExportError("material '%s' reads grid '%s', which the volume does not have (grids: %s)"
                          % (mat.name, grid, ", ".join(grid_names) or "none"))
    sig_t = [sig_s[c] + sig_a[c] for c in range(3)]
    if any(not math.isfinite(v) or v < 0 for v in sig_t):
        raise ExportError("material '%s': negative or non-finite density" % mat.name)
    if max(sig_t) <= 0.0:
        raise ExportError("material '%s' has zero density: nothing to scatter" % mat.name)
    albedo = [min(max(sig_s[c] / sig_t[c], 0.0), 1.0) if sig_t[c] > 0 else 0.0 for c in range(3)]
    if not (-1.0 < g < 1.0):
        raise ExportError("material '%s': anisotropy %g outside (-1, 1)" % (mat.name, g))
    g = max(min(g, 0.999), -0.999)
    return {"grid": grid, "density_scale": sig_t, "albedo": albedo, "g": g}


def render_material(obj, depsgraph):
    """The material Blender renders the volume with: the evaluated object's (a volume made by
    Geometry Nodes carries only what its Set Material nodes give it, not the object's slots)."""
    ev = obj.evaluated_get(depsgraph)
    mat = ev.active_material or next((s.material for s in ev.material_slots if s.material), None)
    if mat is not None:
        return mat
    if any(s.material for s in obj.material_slots):
        raise ExportError("the volume that the modifiers of '%s' produce has no material, so Blender renders it "
                          "with the default volume shader, not '%s': add a Set Material node at the end of its "
                          "Geometry Nodes" % (obj.name, next(s.material for s in obj.material_slots if s.material).name))
    return None


# ---------------------------------------------------------------------------------------------
# Lights, world, camera


def _light_scale(light):
    s = float(light.energy)
    exp = getattr(light, "exposure", 0.0)
    if exp:
        s *= 2.0 ** float(exp)
    return s


def _light_color(light, warnings):
    col = [float(c) for c in light.color]
    if getattr(light, "use_temperature", False):
        warnings.append("light '%s': colour temperature is ignored" % light.name)
    return col


# Which light types a solver handles comes from the library's solver registry
# (native.solvers(): each solver's "lights", in scene JSON light types, "emission" for an
# emissive medium). The operator's error and warning and the solver menu's tooltips are made
# from it.

_BLENDER_LIGHT_NAMES = {"distant": "sun", "point": "point", "spot": "spot", "rect": "area", "disk": "area",
                        "dome": "world", "emission": "volume emission"}


def solver_light_types(name):
    """The scene JSON light types solver `name` handles (empty for an unknown solver)."""
    entry = native.solver(name)
    return tuple(entry["lights"]) if entry else ()


def lights_note(types):
    """Light types `types` in Blender's words, for messages: "sun, point, spot and area lights,
    the world and volume emission"."""
    names = []
    for k in types:
        n = _BLENDER_LIGHT_NAMES.get(k, k)
        if n not in names:
            names.append(n)
    lamps = [n for n in names if n not in ("world", "volume emission")]
    items = []
    if lamps:
        items.append((", ".join(lamps[:-1]) + " and " + lamps[-1] if len(lamps) > 1 else lamps[0]) + " lights")
    items += ["the world" if n == "world" else n for n in names if n in ("world", "volume emission")]
    if not items:
        return "no lights"
    return ", ".join(items[:-1]) + " and " + items[-1] if len(items) > 1 else items[0]


def light_messages(solver, kinds):
    """(error, warning) for a solve by `solver` of lights of scene JSON types `kinds`; None for
    none. The reference (the ground truth) renders a scene it has
    no light for as it is (black); the others refuse it."""
    handled = solver_light_types(solver)
    entry = native.solver(solver) or {"label": solver}
    reference = native.solver("reference") or {"name": "reference", "label": "Reference"}
    note = lights_note(handled)
    if solver != reference["name"] and not any(k in handled for k in kinds):
        return ("the %s solver handles %s, and the scene has none; choose the %s solver"
                % (entry["label"], note, reference["label"]), None)
    left = []
    for k in kinds:
        n = _BLENDER_LIGHT_NAMES.get(k, k)
        if k not in handled and n not in left:
            left.append(n)
    if not left:
        return None, None
    items = ["the world" if n == "world" else n + " lights" for n in left]
    what = items[0] if len(items) == 1 else ", ".join(items[:-1]) + " and " + items[-1]
    verb = "is" if items == ["the world"] else "are"
    return None, ("the %s solver handles %s: %s %s left out (choose %s to include them)"
                  % (entry["label"], note, what, verb, reference["label"]))


def pop_lights_note():
    """What pop handles, in Blender's words (from the registry)."""
    return lights_note(solver_light_types("pop"))


def pop_light_messages(kinds):
    """`light_messages` for pop."""
    return light_messages("pop", kinds)


def _axis_lengths(m3):
    return [m3.col[i].length for i in range(3)]


def _spot(orig, light, m, col, warnings):
    p = _light_scale(light) / (4.0 * math.pi)  # axis intensity of a spot of P watts = a point's
    if p <= 0:
        return None
    m3 = m.to_3x3()
    sx, sy, _ = _axis_lengths(m3)
    if abs(sx - sy) > 1e-4 * max(sx, sy):
        warnings.append("light '%s': a spot under non-uniform object scale has an elliptical cone in Cycles; "
                        "exported with a round cone" % orig.name)
    d = (m3 @ _vec((0.0, 0.0, -1.0))).normalized()
    half = min(max(math.degrees(float(light.spot_size)) / 2.0, 1e-3), 180.0)
    return {"type": "spot", "position": list(m.translation), "direction": list(d), "intensity": [c * p for c in col],
            "cone_half_angle_deg": half, "blend": min(max(float(light.spot_blend), 0.0), 1.0),
            "radius": max(float(light.shadow_soft_size), 0.0)}


def _area(orig, light, m, col, warnings):
    power = _light_scale(light)
    if power <= 0:
        return None
    spread = float(getattr(light, "spread", math.pi))
    if spread < math.pi - 1e-4:
        warnings.append("light '%s': area light spread %.1f degrees is exported as 180 (Lambertian)"
                        % (orig.name, math.degrees(spread)))
    m3 = m.to_3x3()
    sx, sy, _ = _axis_lengths(m3)
    normal = (m3 @ _vec((0.0, 0.0, -1.0))).normalized()
    tangent = (m3 @ _vec((1.0, 0.0, 0.0))).normalized()
    size_x = float(light.size)
    size_y = float(light.size_y) if light.shape in ('RECTANGLE', 'ELLIPSE') else size_x
    w, h = size_x * sx, size_y * sy  # world sizes: Cycles scales the light by its object's scale
    if w <= 0 or h <= 0:
        return None
    pos = list(m.translation)
    if light.shape in ('SQUARE', 'RECTANGLE'):
        area = w * h
        return {"type": "rect", "position": pos, "normal": list(normal), "tangent": list(tangent), "size": [w, h],
                "radiance": [c * power / (math.pi * area) for c in col]}
    # DISK, ELLIPSE: a disk of the same area (exact for a round one)
    area = math.pi * w * h / 4.0
    if abs(w - h) > 1e-4 * max(w, h):
        warnings.append("light '%s': an elliptical area light (%.3g x %.3g m) is exported as a disk of the same area"
                        % (orig.name, w, h))
    return {"type": "disk", "position": pos, "normal": list(normal), "radius": math.sqrt(w * h) / 2.0,
            "radiance": [c * power / (math.pi * area) for c in col]}


def lights(scene, depsgraph, warnings):
    out = []
    for inst in depsgraph.object_instances:
        ob = inst.object
        if ob.type != 'LIGHT':
            continue
        orig = ob.original
        if orig.hide_render:
            continue
        if not getattr(orig, "visible_volume_scatter", True):  # Cycles: light not seen by volumes
            warnings.append("light '%s' has volume scattering visibility off and was left out" % orig.name)
            continue
        light = ob.data
        m = inst.matrix_world
        col = _light_color(light, warnings)
        if getattr(light, "use_nodes", False) and light.node_tree:
            warnings.append("light '%s': its node tree is ignored" % orig.name)
        if light.type == 'SUN':
            d = (m.to_3x3() @ _vec((0.0, 0.0, -1.0))).normalized()
            e = _light_scale(light)
            if e <= 0:
                continue
            out.append({"type": "distant", "direction": list(d), "irradiance": [c * e for c in col],
                        "angle_deg": min(math.degrees(float(light.angle)), 179.0)})
        elif light.type == 'POINT':
            p = _light_scale(light) / (4.0 * math.pi)
            if p <= 0:
                continue
            out.append({"type": "point", "position": list(m.translation), "intensity": [c * p for c in col],
                        "radius": max(float(light.shadow_soft_size), 0.0), "interior": "lit"})
        elif light.type == 'SPOT':
            js = _spot(orig, light, m, col, warnings)
            if js:
                out.append(js)
        elif light.type == 'AREA':
            js = _area(orig, light, m, col, warnings)
            if js:
                out.append(js)
        else:
            warnings.append("light '%s': %s lights are not supported by volscatter yet and were left out"
                            % (orig.name, light.type.lower()))
    return out


def _vec(t):
    from mathutils import Vector
    return Vector(t)


def world_lights(scene, warnings):
    world = scene.world
    if world is None:
        return []
    # Blender 5 always uses the node tree (use_nodes is deprecated there); 4.x may not
    use_nodes = world.use_nodes if bpy.app.version < (5, 0, 0) else True
    tree = world.node_tree if use_nodes else None
    if tree is None:
        c = [float(v) for v in world.color]
        return [{"type": "dome", "color": c}] if max(c) > 0 else []
    outs = [n for n in tree.nodes if n.type == 'OUTPUT_WORLD']
    outs = [n for n in outs if n.is_active_output] or outs
    if not outs or not outs[0].inputs["Surface"].is_linked:
        return []
    node = outs[0].inputs["Surface"].links[0].from_node
    if node.type != 'BACKGROUND' or node.inputs["Strength"].is_linked:
        return _baked_world(world, warnings)
    strength = node.inputs["Strength"]
    s = float(strength.default_value)
    colsock = node.inputs["Color"]
    if s <= 0:
        return []
    if colsock.is_linked:
        src = colsock.links[0].from_node
        img = getattr(src, "image", None)
        if src.type == 'TEX_ENVIRONMENT' and img is not None and img.filepath and \
                getattr(src, "projection", 'EQUIRECTANGULAR') == 'EQUIRECTANGULAR' and \
                not src.inputs["Vector"].is_linked and img.filepath.lower().endswith(".exr"):
            path = _abs(img.filepath, img.library)
            if os.path.isfile(path):
                return [{"type": "dome", "texture": path, "intensity": s}]
        return _baked_world(world, warnings)
    c = [float(v) * s for v in _rgb(colsock)]
    return [{"type": "dome", "color": c}] if max(c) > 0 else []


def _baked_world(world, warnings):
    """A world built from nodes (a Sky Texture, ...): rendered alone into a map for the dome
    light, its sun disc as a distant light (world_bake.py)."""
    from . import world_bake
    try:
        lights, _ = world_bake.bake(world)
    except Exception as e:  # a bake that fails leaves the world out, said
        warnings.append("world '%s': baking its nodes to an environment map failed (%s); the world light was "
                        "left out" % (world.name, e))
        return []
    return lights


def render_size(scene):
    r = scene.render
    w = max(1, int(r.resolution_x * r.resolution_percentage / 100))
    h = max(1, int(r.resolution_y * r.resolution_percentage / 100))
    return w, h


def camera(scene, warnings, size=None):
    cam_ob = scene.camera
    if cam_ob is None:
        raise ExportError("the scene has no active camera (the scattering grid is computed towards it)")
    cam = cam_ob.data
    if cam.type != 'PERSP':
        raise ExportError("camera '%s' is %s; only perspective cameras are supported" % (cam_ob.name, cam.type.lower()))
    w, h = size or render_size(scene)
    r = scene.render
    aspect = (w * r.pixel_aspect_x) / (h * r.pixel_aspect_y)
    if r.pixel_aspect_x != r.pixel_aspect_y:
        warnings.append("non-square pixel aspect is ignored by volscatter")
    if cam.shift_x or cam.shift_y:
        warnings.append("camera '%s': lens shift is ignored" % cam_ob.name)
    fit = cam.sensor_fit
    if fit == 'AUTO':
        horizontal = aspect >= 1.0
        sensor = cam.sensor_width
    elif fit == 'HORIZONTAL':
        horizontal, sensor = True, cam.sensor_width
    else:
        horizontal, sensor = False, cam.sensor_height
    half = math.atan(sensor / (2.0 * cam.lens))
    if horizontal:
        fov = 2.0 * half
    else:
        fov = 2.0 * math.atan(math.tan(half) * aspect)
    fov_deg = math.degrees(fov)
    if not (0.0 < fov_deg < 179.0):
        raise ExportError("camera '%s': horizontal field of view %.1f deg is outside (0, 179)" % (cam_ob.name, fov_deg))
    m = cam_ob.matrix_world
    pos = m.translation
    rot = m.to_3x3()
    fwd = (rot @ _vec((0.0, 0.0, -1.0))).normalized()
    up = (rot @ _vec((0.0, 1.0, 0.0))).normalized()
    return {"position": list(pos), "look_at": list(pos + fwd), "up": list(up), "fov_deg": fov_deg,
            "width": int(w), "height": int(h)}


def matrix_rows(m):
    return [float(m[r][c]) for r in range(4) for c in range(4)]


# ---------------------------------------------------------------------------------------------


def export(context, obj, out_dir, frame, solver=None, size=None, max_resolution=0):
    """-> (scene_dict, warnings, generated_files). Raises ExportError. `max_resolution` > 0:
    the medium's `max_resolution` (the VDB box-filtered as it is read)."""
    scene = context.scene
    warnings = []
    depsgraph = context.evaluated_depsgraph_get()
    cam = camera(scene, warnings, size)  # checked first: cheapest and most common mistake
    if obj is None or obj.type != 'VOLUME':
        raise ExportError("select a Volume object (active object: %s)" % (obj.name if obj else "none"))
    mat = render_material(obj, depsgraph)
    vdb, names, generated = volume_vdb(obj, depsgraph, out_dir, frame)
    try:
        med = material_params(mat, names, warnings)
    except ExportError:
        if generated:
            _remove(vdb)
        raise
    eval_obj = obj.evaluated_get(depsgraph)
    medium = {"vdb": vdb, "grid": med["grid"], "density_scale": med["density_scale"],
              "albedo": med["albedo"], "g": med["g"], "transform": matrix_rows(eval_obj.matrix_world)}
    if med.get("emission"):
        medium["emission"] = med["emission"]
    if max_resolution > 0:
        medium["max_resolution"] = int(max_resolution)
    ls = lights(scene, depsgraph, warnings) + world_lights(scene, warnings)
    if not ls and "emission" not in medium:
        if generated:
            _remove(vdb)
        raise ExportError("no light reaches the volume: add a sun, point, spot or area light (or a world colour, or volume emission)")
    doc = {"format": FORMAT, "medium": medium, "lights": ls, "camera": cam}
    if solver:
        doc["solver"] = solver
    return doc, warnings, [vdb] if generated else []


def _remove(path):
    try:
        os.remove(path)
    except OSError:
        pass
