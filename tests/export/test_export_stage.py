"""The exported stage: what usdchecker's validators say of both demo scenes, its metadata, the
st primvar, native instancing, and the failures that must leave nothing behind."""

import json
import logging
import shutil

import numpy as np
import pytest
from pxr import Sdf, Usd, UsdGeom, UsdLux, UsdShade

from invrender.cli import main
from invrender.export import export_usd, validate_usd
from invrender.export import stage as export_stage
from invrender.export.check import validators
from invrender.scene.format import load_scene, read_scene_json
from invrender.scene.types import SceneError


@pytest.mark.parametrize("name", ["room", "cans"])
@pytest.mark.parametrize("layer", ["scene.usda", "scene.usdc"])
def test_both_demo_exports_pass_the_validators(demo_exports, name, layer):
    assert validate_usd(demo_exports[name] / layer) == []


def test_the_validators_find_errors_where_there_are_some(tmp_path):
    """The check is not vacuous: it runs the stage-metadata, composition and reference checks, and a
    stage without units, up axis or default prim, with a missing texture, fails it."""
    names = {v.GetMetadata().name for v in validators()}
    assert {
        "usdGeomValidators:StageMetadataChecker",
        "usdValidation:StageMetadataChecker",
        "usdUtilsValidators:MissingReferenceValidator",
        "usdShadeValidators:ShaderSdrCompliance",
    } <= names
    stage = Usd.Stage.CreateNew(str(tmp_path / "bad.usda"))
    UsdGeom.Xform.Define(stage, "/World")
    shader = UsdShade.Shader.Define(stage, "/World/Looks/m/tex")
    shader.CreateIdAttr("UsdUVTexture")
    shader.CreateInput("file", Sdf.ValueTypeNames.Asset).Set("./missing.exr")
    stage.GetRootLayer().Save()
    errors = " | ".join(validate_usd(tmp_path / "bad.usda"))
    for expected in ("metersPerUnit", "upAxis", "defaultPrim", "missing.exr"):
        assert expected in errors, errors


@pytest.mark.parametrize("name", ["room", "cans"])
def test_stage_metadata_meters_y_up_default_prim(demo_exports, name):
    stage = Usd.Stage.Open(str(demo_exports[name] / "scene.usda"))
    assert UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.y
    assert stage.GetDefaultPrim().GetPath() == Sdf.Path("/Scene")
    summary = json.loads((demo_exports[name] / "export.json").read_text())
    assert summary["layers"] == ["scene.usda", "scene.usdc"]


def test_room_splits_lights_and_windows_as_milo_exports_them(demo_dirs, demo_exports):
    scene = load_scene(demo_dirs["room"])
    metadata = read_scene_json(demo_dirs["room"])["metadata"]
    stage = Usd.Stage.Open(str(demo_exports["room"] / "scene.usda"))
    lights = [p for p in stage.Traverse() if p.HasAPI(UsdLux.MeshLightAPI)]
    panels = [p for p in metadata["parts"] if p["emitter"]]
    assert len(lights) == len(panels) == 2
    for prim in lights:
        light = UsdLux.LightAPI(prim)
        assert light.GetMaterialSyncModeAttr().Get() == UsdLux.Tokens.independent
        radiance = np.asarray(light.GetColorAttr().Get()) * light.GetIntensityAttr().Get()
        # the generator's panels: light_radiance x light_color at the centre, falling off to
        # (1 - light_falloff) of it at the edge, so the mean lies strictly between the two
        config = metadata["config"]
        centre = config["light_radiance"] * np.asarray(config["light_color"])
        assert np.all(radiance < centre) and np.all(radiance > (1 - config["light_falloff"]) * centre)
        material = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial()[0]
        emissive = material.ComputeSurfaceSource()[0].GetInput("emissiveColor")
        assert emissive.HasConnectedSource()  # the texture-exact emission stays in emissiveColor
    window = stage.GetPrimAtPath("/Scene/Geometry/window_0")
    assert UsdGeom.Imageable(window).ComputeVisibility() == UsdGeom.Tokens.invisible
    window_part = next(p for p in metadata["parts"] if p["window"])
    assert len(UsdGeom.Mesh(window).GetFaceVertexCountsAttr().Get()) == np.diff(window_part["faces"])[0]
    dome = UsdLux.DomeLight(stage.GetPrimAtPath("/Scene/Lights/sky"))
    assert dome.GetTextureFormatAttr().Get() == UsdLux.Tokens.latlong
    faces = sum(len(UsdGeom.Mesh(p).GetFaceVertexCountsAttr().Get()) for p in stage.Traverse() if p.IsA(UsdGeom.Mesh))
    assert faces == len(scene.mesh.faces)


def _flattened_st(prim):
    """(corner uv (k, 2), corner point (k, 3)) of a mesh prim as USD tools see it."""
    mesh = UsdGeom.Mesh(prim)
    st = UsdGeom.PrimvarsAPI(prim).GetPrimvar("st")
    values = np.asarray(st.ComputeFlattened())
    corners = np.asarray(mesh.GetFaceVertexIndicesAttr().Get())
    points = np.asarray(mesh.GetPointsAttr().Get())
    if st.GetInterpolation() == UsdGeom.Tokens.vertex:
        values = values[corners]
    return values, points[corners]


def test_st_is_face_varying_where_the_atlas_has_seams_and_reads_like_the_scene(demo_dirs, demo_exports):
    scene = load_scene(demo_dirs["room"])
    stage = Usd.Stage.Open(str(demo_exports["room"] / "scene.usda"))
    interpolations = set()
    for prim in stage.Traverse():
        if not prim.IsA(UsdGeom.Mesh):
            continue
        interpolations.add(UsdGeom.PrimvarsAPI(prim).GetPrimvar("st").GetInterpolation())
        faces = np.asarray(prim.GetAttribute("invrender:faceIndices").Get())
        uv, points = _flattened_st(prim)
        corners = scene.mesh.faces[faces].ravel()
        assert np.array_equal(uv, scene.mesh.uvs[corners]), prim.GetPath()
        assert np.array_equal(points, scene.mesh.positions[corners]), prim.GetPath()
        welded = len(prim.GetAttribute("points").Get())
        assert welded == len(np.unique(scene.mesh.positions[corners], axis=0))
    assert UsdGeom.Tokens.faceVarying in interpolations  # the room's atlas has seams


def test_duplicates_are_native_instances_of_one_prototype(demo_dirs, demo_exports):
    scene = load_scene(demo_dirs["cans"])
    poses = read_scene_json(demo_dirs["cans"])["metadata"]["poses"]["instances"]
    stage = Usd.Stage.Open(str(demo_exports["cans"] / "scene.usda"))
    instances = [p for p in stage.Traverse() if p.IsInstance()]
    assert len(instances) == len(poses) == 6
    assert len(stage.GetPrototypes()) == 1  # one prototype mesh (and material) shared by all
    for prim in instances:
        instance_id = prim.GetAttribute("invrender:instanceId").Get()
        pose = next(p for p in poses if p["instance_id"] == instance_id)
        matrix = np.array(UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(Usd.TimeCode.Default())).T
        assert np.allclose(matrix, pose["T_obj2world"], atol=1e-15)
        mesh = next(p for p in Usd.PrimRange(prim, Usd.TraverseInstanceProxies()) if p.IsA(UsdGeom.Mesh))
        assert mesh.IsInstanceProxy()
        _, points = _flattened_st(mesh)
        world = points @ matrix[:3, :3].T + matrix[:3, 3]
        faces = np.asarray(prim.GetAttribute("invrender:faceIndices").Get())
        assert np.abs(world - scene.mesh.positions[scene.mesh.faces[faces].ravel()]).max() < 1e-6


def test_instancing_can_be_turned_off_and_a_pose_that_does_not_fit_is_refused(demo_dirs, tmp_path, caplog):
    summary = export_usd(demo_dirs["cans"], tmp_path / "plain", instancing=False)
    assert summary["prims"]["instances"] == 0 and summary["prims"]["surfaces"] == 7
    poses = read_scene_json(demo_dirs["cans"])["metadata"]["poses"]
    poses["instances"][2]["T_obj2world"][0][3] += 0.01  # one copy 1 cm off its recorded pose
    (tmp_path / "poses.json").write_text(json.dumps(poses))
    with caplog.at_level(logging.WARNING):
        summary = export_usd(demo_dirs["cans"], tmp_path / "shifted", poses=tmp_path / "poses.json")
    assert summary["prims"]["instances"] == 5 and summary["prims"]["surfaces"] == 2
    assert "instance 3 is not a copy of the prototype" in caplog.text


def test_a_missing_texture_fails_with_its_name_and_writes_nothing(demo_dirs, tmp_path):
    scene_dir = tmp_path / "scene"
    shutil.copytree(demo_dirs["room"], scene_dir)
    (scene_dir / "maps" / "kd.exr").unlink()
    with pytest.raises(SceneError, match=r"maps\.kd.*kd\.exr does not exist"):
        export_usd(scene_dir, tmp_path / "export")
    assert list(tmp_path.iterdir()) == [scene_dir]


def test_an_unwritable_output_fails_clearly_and_leaves_no_partial_usda(demo_dirs, tmp_path, capsys):
    blocker = tmp_path / "a_file"
    blocker.write_text("not a directory")
    with pytest.raises(SceneError, match="a_file: output: expected a directory to hold .*; it is a file"):
        export_usd(demo_dirs["room"], blocker / "export")
    assert main(["export", str(demo_dirs["room"]), "--out", str(blocker / "export")]) == 2
    assert "a_file: output: expected a directory to hold" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.rglob("*")) == ["a_file"]


def test_a_failure_after_writing_started_keeps_the_previous_export_whole(demo_dirs, tmp_path, monkeypatch):
    out = tmp_path / "export"
    export_usd(demo_dirs["room"], out)
    before = {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()}
    monkeypatch.setattr(export_stage, "validate_usd", lambda path: ["usdGeomValidators:Something: broken"])
    with pytest.raises(RuntimeError, match="fails validation"):
        export_usd(demo_dirs["room"], out, usdc=True)
    after = {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()}
    assert after == before  # the old export, whole; no scene.usdc, no temporary directory beside it
    assert sorted(p.name for p in tmp_path.iterdir()) == ["export"]
