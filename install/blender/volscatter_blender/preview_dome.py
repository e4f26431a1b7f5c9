"""Preview's dim-world shortcut for pop: Blender's default world (grey 0.05) becomes a dome that
pop approximates by 16 ordinates placed by an importance pass, most of a small smoke's Preview
solve. When the world brings little of the light, Preview passes 6 ordinates without the
importance pass instead. "Little" was measured (scripts/bench_preview_dome.py, BENCHMARKS.md
section `preview-dome`, plume 32^3 under a sun): up to a world share of 30% the image's error
against the reference rises from 0.139 to 0.144 (0.140 -> 0.143 at the default grey's 17%),
beyond it by more (0.136 -> 0.148 at 68%). No bpy here: it works on the exported scene JSON."""
import math

#: Largest share of the fluence at the volume's centre a world may bring for the shortcut.
SMALL_SHARE = 0.30
#: What a small world gets in Preview (pop's defaults: 16 ordinates with importance).
FEW_ORDINATES = {"dome_ordinates": 6, "dome_importance": False}


def _dist2(a, b):
    return max(sum((x - y) ** 2 for x, y in zip(a, b)), 1e-6)


def world_share(lights, centre):
    """The world's share of the fluence (W/m^2, all directions) at `centre` from the scene
    JSON's `lights`: a dome of radiance L gives 4 pi L, a sun its irradiance, point and spot
    lights intensity / d^2, area lights radiance x area / d^2 (their most, facing the centre).
    None when there is no constant-colour dome (a texture's mean is not known here)."""
    world = lamps = 0.0
    has_dome = False
    for l in lights:
        t = l["type"]
        if t == "dome":
            if "color" not in l:
                return None
            has_dome = True
            world += 4 * math.pi * max(l["color"])
        elif t == "distant":
            lamps += max(l["irradiance"])
        elif t in ("point", "spot"):
            lamps += max(l["intensity"]) / _dist2(l["position"], centre)
        elif t == "rect":
            lamps += max(l["radiance"]) * l["size"][0] * l["size"][1] / _dist2(l["position"], centre)
        elif t == "disk":
            lamps += max(l["radiance"]) * math.pi * l["radius"] ** 2 / _dist2(l["position"], centre)
    if not has_dome or world + lamps <= 0:
        return None
    return world / (world + lamps)


def apply(doc, centre):
    """Gives the solver in `doc` (pop's Preview) the few ordinates when the world is small and
    returns the report's note, else None. Settings the solver JSON already names are kept."""
    share = world_share(doc["lights"], centre)
    if share is None or share > SMALL_SHARE:
        return None
    solver = doc["solver"]
    if any(k in solver for k in FEW_ORDINATES):
        return None
    solver.update(FEW_ORDINATES)
    return ("volscatter: Preview: the world brings %.0f%% of the light (at most %.0f%%), so pop approximates it by "
            "%d directions without importance (Final uses 16 with importance)"
            % (100 * share, 100 * SMALL_SHARE, FEW_ORDINATES["dome_ordinates"]))
