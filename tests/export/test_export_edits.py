"""An exported stage edited the way another tool edits it (pxr calls standing in for Blender or
Omniverse), then imported: the edits are what comes back, and nothing else changes."""

import shutil

import cv2
import numpy as np
import pytest
from pxr import Gf, Sdf, Usd, UsdGeom, UsdLux, UsdRender, UsdShade

from invrender.export import import_usd
from invrender.scene.format import load_scene, read_scene_json
from invrender.scene.images import srgb_to_linear
from invrender.scene.regions import face_texels


@pytest.fixture
def edited(demo_exports, tmp_path):
    """A copy of an export to edit: edited(name) -> (stage, directory)."""

    def copy(name):
        target = tmp_path / f"{name}_usd"
        shutil.copytree(demo_exports[name], target)
        return Usd.Stage.Open(str(target / "scene.usda")), target

    return copy


def _import(stage, tmp_path, **kwargs):
    stage.GetRootLayer().Save()
    out = tmp_path / "imported"
    import_usd(stage.GetRootLayer().realPath, out, **kwargs)
    return load_scene(out)


def _texels(scene, faces):
    return np.unique(face_texels(scene.mesh.uvs, scene.mesh.faces[faces], scene.maps.atlas_shape)[1])


def test_a_moved_instance_moves_and_nothing_else_does(edited, demo_dirs, tmp_path):
    stage, _ = edited("cans")
    prim = stage.GetPrimAtPath("/Scene/Geometry/object_3")
    op = UsdGeom.Xformable(prim).GetOrderedXformOps()[0]
    op.Set(op.Get() * Gf.Matrix4d().SetTranslate(Gf.Vec3d(0.1, 0.0, -0.05)))  # world +X 10 cm, -Z 5 cm
    back = _import(stage, tmp_path)
    original = load_scene(demo_dirs["cans"])
    moved = np.isin(np.arange(len(original.mesh.positions)), original.mesh.faces[original.mesh.instance_ids == 3])
    shift = back.mesh.positions - original.mesh.positions
    assert np.allclose(shift[moved], [0.1, 0.0, -0.05], atol=1e-6)
    assert np.abs(shift[~moved]).max() < 1e-7

    def pose_of(directory):
        instances = read_scene_json(directory)["metadata"]["poses"]["instances"]
        return np.asarray(next(p for p in instances if p["instance_id"] == 3)["T_obj2world"])

    assert np.allclose(
        pose_of(tmp_path / "imported")[:3, 3] - pose_of(demo_dirs["cans"])[:3, 3], [0.1, 0.0, -0.05], atol=1e-12
    )  # the pose follows, so the next export instances it there


def test_a_changed_material_is_baked_under_its_faces_only(edited, demo_dirs, tmp_path):
    stage, _ = edited("cans")
    surface = UsdShade.Shader(stage.GetPrimAtPath("/Scene/Prototypes/object/Looks/atlas/surface"))
    diffuse = surface.GetInput("diffuseColor")
    diffuse.DisconnectSource()
    diffuse.Set(Gf.Vec3f(0.8, 0.05, 0.02))  # the cans painted red
    back = _import(stage, tmp_path)
    original = load_scene(demo_dirs["cans"])
    cans = _texels(original, np.flatnonzero(original.mesh.instance_ids > 0))
    floor = np.setdiff1d(_texels(original, np.flatnonzero(original.mesh.instance_ids == 0)), cans)
    kd_back, kd_original = back.maps.kd.reshape(-1, 3), original.maps.kd.reshape(-1, 3)
    assert np.allclose(kd_back[cans], [0.8, 0.05, 0.02])
    assert np.array_equal(kd_back[floor], kd_original[floor])
    for name in ("ks", "ka", "ke"):  # the other inputs still read the export's textures
        assert np.array_equal(getattr(back.maps, name), getattr(original.maps, name)), name


@pytest.mark.parametrize("color_space, decode", [("sRGB", True), ("auto", True), ("raw", False)])
def test_an_8bit_png_texture_is_read_in_the_colour_space_it_declares(edited, tmp_path, color_space, decode):
    stage, directory = edited("room")
    rng = np.random.default_rng(1)
    values = rng.integers(0, 256, (256, 256, 3), dtype=np.uint8)
    cv2.imwrite(str(directory / "textures" / "painted.png"), values[:, :, ::-1])  # OpenCV writes BGR
    texture = UsdShade.Shader(stage.GetPrimAtPath("/Scene/Looks/atlas/kd"))
    texture.GetInput("file").Set("./textures/painted.png")
    texture.GetInput("sourceColorSpace").Set(color_space)
    back = _import(stage, tmp_path)
    expected = srgb_to_linear(values / 255.0) if decode else values / 255.0  # IEC 61966-2-1
    assert np.abs(back.maps.kd - expected).max() < 1e-6


def test_an_edited_light_intensity_scales_the_exact_emission(edited, demo_dirs, tmp_path):
    stage, _ = edited("room")
    prim = stage.GetPrimAtPath("/Scene/Lights/light_1")
    light = UsdLux.LightAPI(prim)
    light.GetIntensityAttr().Set(light.GetIntensityAttr().Get() * 2)
    back = _import(stage, tmp_path)
    original = load_scene(demo_dirs["room"])
    faces = np.asarray(prim.GetAttribute("invrender:faceIndices").Get())
    other = np.asarray(stage.GetPrimAtPath("/Scene/Lights/light_0").GetAttribute("invrender:faceIndices").Get())
    lit, unlit = _texels(original, faces), _texels(original, other)
    ke_back, ke_original = back.maps.ke.reshape(-1, 3), original.maps.ke.reshape(-1, 3)
    assert np.allclose(ke_back[lit], 2 * ke_original[lit], rtol=1e-5)
    assert np.array_equal(ke_back[unlit], ke_original[unlit])


def test_an_edited_roughness_replaces_the_exact_ka(edited, tmp_path):
    stage, _ = edited("room")
    roughness = UsdShade.Shader(stage.GetPrimAtPath("/Scene/Looks/atlas/surface")).GetInput("roughness")
    roughness.DisconnectSource()
    roughness.Set(0.5)
    back = _import(stage, tmp_path)
    assert np.allclose(back.maps.ka, 0.5**4)


def test_a_foreign_stage_in_centimetres_z_up_with_quads(tmp_path):
    """Not ours: no invrender: attributes, quads, vertex st, a constant material, Z up, cm."""
    stage = Usd.Stage.CreateNew(str(tmp_path / "foreign.usda"))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, 0.01)
    mesh = UsdGeom.Mesh.Define(stage, "/World/floor")
    mesh.CreatePointsAttr([(0, 0, 0), (100, 0, 0), (100, 100, 0), (0, 100, 0), (0, 0, 100)])
    mesh.CreateFaceVertexCountsAttr([4, 3])
    mesh.CreateFaceVertexIndicesAttr([0, 1, 2, 3, 0, 1, 4])
    st = UsdGeom.PrimvarsAPI(mesh).CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.vertex)
    st.Set([(0, 0), (1, 0), (1, 1), (0, 1), (0.5, 0.5)])
    material = UsdShade.Material.Define(stage, "/World/m")
    shader = UsdShade.Shader.Define(stage, "/World/m/s")
    shader.CreateIdAttr("UsdPreviewSurface")
    shader.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).Set((0.2, 0.4, 0.6))
    material.CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")
    UsdShade.MaterialBindingAPI.Apply(mesh.GetPrim()).Bind(material)
    camera = UsdGeom.Camera.Define(stage, "/World/camera")
    camera.AddTranslateOp().Set((50, 50, 300))  # looking down -Z: straight down at the floor
    product = UsdRender.Product.Define(stage, "/Render/camera")
    product.CreateCameraRel().SetTargets([camera.GetPath()])
    product.CreateResolutionAttr(Gf.Vec2i(64, 48))
    back = _import(stage, tmp_path)
    assert back.mesh.faces.shape == (3, 3)  # the quad fanned into two triangles
    assert np.allclose(back.mesh.positions[4], [0.0, 1.0, 0.0])  # (0, 0, 100) cm, Z up -> (0, 1, 0) m
    assert np.allclose(back.mesh.positions[2], [1.0, 0.0, -1.0])  # (100, 100, 0) cm -> (1, 0, -1) m
    # no useSpecularWorkflow: the metallic workflow, metallic 0, ior 1.5: F0 = ((1 - 1.5) / (1 + 1.5))^2
    assert np.allclose(back.maps.kd, [0.2, 0.4, 0.6]) and np.allclose(back.maps.ks, 0.04)
    assert np.allclose(back.maps.ka, 0.5**4)  # UsdPreviewSurface's default roughness 0.5
    [cam] = back.cameras
    assert (cam.width, cam.height) == (64, 48) and np.allclose(cam.center, [0.5, 3.0, -0.5])
    assert np.allclose(cam.R @ [0, -1, 0], [0, 0, 1])  # it looks down
