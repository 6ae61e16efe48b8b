"""assets.library: user folders of OBJ/PLY/USD models beside the bundled furniture; USD
transforms, units and up axis applied; one SceneError per unreadable model."""

import numpy as np
import pytest
from pxr import Gf, Usd, UsdGeom, UsdShade

from invrender.assets import library as lib
from invrender.assets.furniture import furniture
from invrender.assets.primitives import signed_volume
from invrender.scene.types import SceneError
from invrender.scene.usd_mesh import read_usd_parts

DESK = furniture("desk", 0)  # asymmetric: a pedestal on one side, drawers at the front


def write_obj(path, asset):
    lines = [f"v {x:.17g} {y:.17g} {z:.17g}" for x, y, z in asset.mesh.positions]
    for k, name in enumerate(asset.part_names):
        lines.append(f"usemtl {name}")
        lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in asset.mesh.faces[asset.mesh.part == k]]
    path.write_text("\n".join(lines) + "\n")


def write_ply(path, asset):
    p, f = asset.mesh.positions, asset.mesh.faces
    head = f"ply\nformat ascii 1.0\nelement vertex {len(p)}\nproperty double x\nproperty double y\nproperty double z\n"
    head += f"element face {len(f)}\nproperty list uchar int vertex_indices\nend_header\n"
    body = "".join(f"{x:.17g} {y:.17g} {z:.17g}\n" for x, y, z in p) + "".join(f"3 {a} {b} {c}\n" for a, b, c in f)
    path.write_text(head + body)


def write_usd(path, asset, left_handed=False):
    """The asset in centimeters, Z up, under a translated and rotated Xform, one mesh per part
    with a material bound."""
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, 0.01)
    xform = UsdGeom.Xform.Define(stage, "/model")
    xform.AddTranslateOp().Set(Gf.Vec3d(300, -200, 0))
    xform.AddRotateZOp().Set(90.0)
    to_file = np.array([[100, 0, 0], [0, 0, -100], [0, 100, 0]], np.float64)  # ours (Y up, m) -> cm, Z up
    for k, name in enumerate(asset.part_names):
        faces = asset.mesh.faces[asset.mesh.part == k]
        mesh = UsdGeom.Mesh.Define(stage, f"/model/{name}_mesh")
        mesh.GetPointsAttr().Set([Gf.Vec3f(*(to_file @ p)) for p in asset.mesh.positions])
        mesh.GetFaceVertexCountsAttr().Set([3] * len(faces))
        mesh.GetFaceVertexIndicesAttr().Set((faces[:, ::-1] if left_handed else faces).ravel().tolist())
        if left_handed:
            mesh.GetOrientationAttr().Set(UsdGeom.Tokens.leftHanded)
        material = UsdShade.Material.Define(stage, f"/model/materials/{name}")
        UsdShade.MaterialBindingAPI.Apply(mesh.GetPrim()).Bind(material)
    stage.Save()


def rotated_back(triangles):
    """Undo the file's rotateZ 90 (in ours a quarter turn about +Y: (x, z) -> (z, -x))."""
    x, y, z = np.moveaxis(triangles, -1, 0)
    return np.stack([-z, y, x], axis=-1)


def triangles_by_part(asset):
    """(F, 3, 3) corner positions, the faces grouped by part (how the files list them)."""
    m = asset.mesh
    return np.concatenate([m.positions[m.faces[m.part == k]] for k in range(len(asset.part_names))])


@pytest.fixture
def folder(tmp_path):
    (tmp_path / "desks").mkdir()
    write_obj(tmp_path / "desks" / "office.obj", DESK)
    write_ply(tmp_path / "Desk_02.ply", DESK)
    write_usd(tmp_path / "desks" / "scan.usda", DESK)
    return tmp_path


def test_user_models_join_the_bundled_furniture(folder):
    assets = lib.library([folder])
    user = {a.name: a for a in assets if a.source != "procedural"}
    root = folder.name
    assert set(user) == {f"{root}/Desk_02", f"{root}/desks/office", f"{root}/desks/scan"}
    assert {a.category for a in user.values()} == {"desk", "desks"}
    obj, ply, usd = user[f"{root}/desks/office"], user[f"{root}/Desk_02"], user[f"{root}/desks/scan"]
    assert obj.part_names == DESK.part_names == usd.part_names and ply.part_names == ("surface",)
    np.testing.assert_allclose(triangles_by_part(obj), triangles_by_part(DESK), atol=1e-6)
    np.testing.assert_allclose(triangles_by_part(ply), DESK.mesh.positions[DESK.mesh.faces], atol=1e-6)
    assert obj.nominal_size == pytest.approx(1.0, abs=1e-6)  # the file's units (the unit desk)
    # USD: centimeters and Z up become meters and Y up; the rotation stays (a model's pose is its own).
    assert usd.nominal_size == pytest.approx(1.0, rel=1e-6)
    np.testing.assert_allclose(rotated_back(triangles_by_part(usd)), triangles_by_part(DESK), atol=1e-5)
    assert signed_volume(usd.mesh.positions, usd.mesh.faces) > 0


def test_usd_transform_units_and_left_handed_winding(tmp_path):
    write_usd(tmp_path / "l.usda", DESK, left_handed=True)
    parts = read_usd_parts(tmp_path / "l.usda")
    positions = np.concatenate([p for _, p, _ in parts])
    # World = rotateZ(90) then translate (300, -200, 0) cm, Z up -> ours: (x, z, -y) in meters.
    lo = positions.min(axis=0)
    assert lo[1] == pytest.approx(0, abs=1e-6)  # the desk's feet stay on the floor
    centre = 0.5 * (positions.min(axis=0) + positions.max(axis=0))
    assert centre[0] == pytest.approx(3.0, abs=0.02) and centre[2] == pytest.approx(2.0, abs=0.02)
    assert sum(signed_volume(p, f) for _, p, f in parts) > 0  # left-handed fronts flipped back outwards


@pytest.mark.parametrize(
    "name, text, field",
    [
        ("bad.usda", "#usda 1.0\n(\n  this is not usd\n", "(file)"),
        ("empty.usda", "#usda 1.0\ndef Xform \"a\" {}\n", "UsdGeom.Mesh"),
        ("bad.obj", "v 0 0 0\nv 1 0 zero\nf 1 2 3\n", "line 2 v"),
        ("bad.ply", "ply\nformat ascii 1.0\nelement vertex 2\n", ""),
    ],
)
def test_an_unreadable_model_is_one_scene_error(tmp_path, name, text, field):
    (tmp_path / name).write_text(text)
    with pytest.raises(SceneError) as error:
        lib.library([tmp_path])
    assert name in str(error.value) and field in str(error.value)


def test_a_folder_without_models(tmp_path):
    with pytest.raises(SceneError, match="at least one model file"):
        lib.user_assets(tmp_path)
    with pytest.raises(SceneError, match="an existing folder"):
        lib.user_assets(tmp_path / "missing")
