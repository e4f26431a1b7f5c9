"""The USD stage the tests and the farm benchmark render: a smoke from a VDB file and a camera
looking at it; the caller adds its lights and frames (not a test module: no test_ prefix)."""

import shutil
from pathlib import Path


def smoke_stage(folder: Path, vdb: Path, name: str = "s.usda", mpu: float = 1.0, vdb_path: str = "vol/d.vdb",
                focal: float | None = 50.0, aperture: tuple[float, float] | None = None):
    """A new stage `folder/name` (Z up, `mpu` metres per unit): /World/Smoke reads a copy of
    `vdb` at `folder/vdb_path` (density scale 5), /World/Cam stands 6 m out on -Y looking at the
    origin. `focal` and `aperture` (horizontal, vertical, mm) are authored when given. Returns
    (stage, path); the caller saves it."""
    from pxr import Gf, Sdf, Usd, UsdGeom, UsdVol

    folder.mkdir(parents=True, exist_ok=True)
    path = folder / name
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, "Z")
    UsdGeom.SetStageMetersPerUnit(stage, mpu)
    (folder / vdb_path).parent.mkdir(parents=True, exist_ok=True)
    shutil.copy(vdb, folder / vdb_path)
    vol = UsdVol.Volume.Define(stage, "/World/Smoke")
    f = UsdVol.OpenVDBAsset.Define(stage, "/World/Smoke/density")
    f.CreateFilePathAttr().Set(Sdf.AssetPath("./" + vdb_path))
    f.CreateFieldNameAttr().Set("density")
    vol.CreateFieldRelationship("density", f.GetPath())
    vol.GetPrim().CreateAttribute("volscatter:densityScale", Sdf.ValueTypeNames.Float).Set(5.0)
    cam = UsdGeom.Camera.Define(stage, "/World/Cam")
    if focal is not None:
        cam.CreateFocalLengthAttr().Set(focal)
    if aperture is not None:
        cam.CreateHorizontalApertureAttr().Set(aperture[0])
        cam.CreateVerticalApertureAttr().Set(aperture[1])
    x = UsdGeom.Xformable(cam)
    x.AddTranslateOp().Set(Gf.Vec3d(0.0, -6.0 / mpu, 0.0))
    x.AddRotateXOp().Set(90.0)
    return stage, path
