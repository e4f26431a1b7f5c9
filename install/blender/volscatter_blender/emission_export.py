"""Principled Volume emission -> the `medium.emission` block of the scene JSON.

Cycles' Principled Volume emits, per metre of path (radiance W/m^3/sr, independent of density):

    Emission Strength * Emission Color
    + Blackbody Intensity * Blackbody Tint * blackbody(T),  T = Temperature * max(grid, 0)

(blackbody: sigma_SB T^4 / pi * 1e-6 times the Rec.709 colour of Planck's spectrum at
luminance 1; volscatter-core medium/blackbody.rs). volscatter reads emission from grids of the
volume's VDB: Emission Strength must come from an Attribute node naming a grid (e.g. "flame"),
optionally through Math Multiply by a constant, like the density; the blackbody from the
Temperature Attribute grid (e.g. "temperature") times the Temperature value, or from an
Attribute node driving Temperature (the form Cycles 5.0.1 renders: with the grid named in
Temperature Attribute it renders the whole volume as a sliver, install/README.md). A constant Emission Strength or a missing
temperature grid would glow uniformly over the volume's bounds in Cycles: left out, with a
warning.
"""


def _rgb(sock):
    v = sock.default_value
    try:
        return [float(v[0]), float(v[1]), float(v[2])]
    except TypeError:
        return [float(v)] * 3


def _constant(sock, what, mat, warnings):
    """The socket's constant value, or None (with a warning) when a node drives it."""
    if sock.is_linked:
        warnings.append("material '%s': Principled Volume %s is driven by a node (%s); its emission is left out"
                        % (mat.name, what, sock.links[0].from_node.name))
        return None
    return sock


def principled_emission(node, mat, grid_names, warnings, grid_expr):
    """-> the JSON emission dict for Principled Volume `node`, or None when it does not emit
    (or emits in a way volscatter cannot read: then `warnings` says so). `grid_expr(link, mat,
    depth)` interprets a grid expression as (grid name, scale), as for the density."""
    inp = node.inputs
    out = {}
    strength = inp.get("Emission Strength")
    if strength is not None and (strength.is_linked or float(strength.default_value) > 1e-5):
        color = _constant(inp["Emission Color"], "Emission Color", mat, warnings)
        if not strength.is_linked:
            warnings.append("material '%s': a constant Emission Strength (no grid) glows over the whole volume box in "
                            "Cycles; volscatter leaves it out (drive it with an Attribute node naming a grid, "
                            "e.g. 'flame')" % mat.name)
        elif color is not None:
            name, scale = grid_expr(strength.links[0], mat, 0)
            if name not in grid_names:
                warnings.append("material '%s': emission grid '%s' is not in the volume (grids: %s); emission left out"
                                % (mat.name, name, ", ".join(grid_names) or "none"))
            elif scale > 0.0:
                out.update(grid=name, strength=float(scale), color=[max(c, 0.0) for c in _rgb(color)])
    bb = inp.get("Blackbody Intensity")
    if bb is not None and (bb.is_linked or float(bb.default_value) > 1e-3):
        bb = _constant(bb, "Blackbody Intensity", mat, warnings)
        tint = _constant(inp["Blackbody Tint"], "Blackbody Tint", mat, warnings)
        temp = inp["Temperature"]
        attr = inp["Temperature Attribute"].default_value if "Temperature Attribute" in inp else ""
        source = None  # (grid, kelvin per unit)
        if temp.is_linked:
            # Temperature = Attribute(grid) [* constant]; Cycles multiplies in the Temperature
            # Attribute too, when it names a grid: a product of two grids is not readable.
            name, scale = grid_expr(temp.links[0], mat, 0)
            if attr and attr in grid_names:
                warnings.append("material '%s': Temperature is driven by grid '%s' and Temperature Attribute names "
                                "grid '%s' too; their product is not supported, blackbody left out" % (mat.name, name, attr))
            elif name in grid_names:
                source = (name, scale)
            else:
                warnings.append("material '%s': temperature grid '%s' is not in the volume; blackbody left out"
                                % (mat.name, name))
        elif attr and attr in grid_names:
            source = (attr, float(temp.default_value))
        else:
            warnings.append("material '%s': blackbody emission needs a temperature grid (Temperature Attribute "
                            "'%s' is not in the volume: grids %s); left out"
                            % (mat.name, attr, ", ".join(grid_names) or "none"))
        if source is not None and None not in (bb, tint):
            out.update(temperature_grid=source[0], temperature=max(source[1], 0.0),
                       blackbody_intensity=float(bb.default_value),
                       blackbody_tint=[max(c, 0.0) for c in _rgb(tint)])
    return out or None
