"""A v2 scene through USD: objects as Xforms with their transforms, the instanced cube as two
instanceable references to one prototype, one material per material set; and back, exactly."""

import numpy as np
import pytest
from pxr import Gf, Usd, UsdGeom, UsdShade
from testscenes import three_objects

from invrender.export import export_usd, import_usd
from invrender.render.features import Features
from invrender.render.renderer import Renderer
from invrender.scene.format import load_scene, write_scene
from invrender.scene.packing import pack_scene

SPP, SEED = 8, 3


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    objects, materials, kg, cameras = three_objects()
    kg[:] = np.linspace(0.2, 1.0, kg.size, dtype=np.float32).reshape(kg.shape)  # a dome too
    objects[1].emission_sides = "one"
    root = tmp_path_factory.mktemp("v2")
    write_scene(root / "scene", pack_scene(objects, materials, kg, cameras))
    summary = export_usd(root / "scene", root / "usd", usdc=True)
    return root, summary


def _render(scene):
    return Renderer(scene, Features.everything(max_bounces=3)).render(scene.cameras[0], spp=SPP, seed=SEED)["radiance"]


def test_objects_are_prims_with_their_transforms_and_instances_share_a_prototype(exported):
    root, summary = exported
    assert summary["prims"]["objects"] == 4 and summary["prims"]["prototypes"] == 1
    assert summary["prims"]["instances"] == 2 and summary["prims"]["lights"] == 1
    stage = Usd.Stage.Open(str(root / "usd" / "scene.usda"))
    scene = load_scene(root / "scene")
    for obj in scene.objects:
        prim = stage.GetPrimAtPath(f"/Scene/Geometry/{obj.name}")
        local = np.array(UsdGeom.Xformable(prim).GetLocalTransformation(), np.float64).T
        assert np.array_equal(local, obj.transform), obj.name
    a, b = (stage.GetPrimAtPath(f"/Scene/Geometry/{n}") for n in ("cube_a", "cube_b"))
    assert a.IsInstance() and b.IsInstance() and a.GetPrototype() == b.GetPrototype()
    assert not stage.GetPrimAtPath("/Scene/Geometry/room").IsInstance()
    bound = {}
    for prim in stage.Traverse(Usd.TraverseInstanceProxies(Usd.PrimDefaultPredicate)):
        if prim.IsA(UsdGeom.Mesh):
            material = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial()[0]
            shader = UsdShade.Shader(stage.GetPrimAtPath(material.GetPath().AppendChild("kd")))
            bound[str(prim.GetPath()).split("/")[3]] = shader.GetInput("file").Get().path
    assert bound == {
        "room": "./textures/walls/kd.exr",
        "table": "./textures/wood/kd.exr",
        "cube_a": "./textures/paint/kd.exr",
        "cube_b": "./textures/paint/kd.exr",
    }


@pytest.mark.parametrize("layer", ["scene.usda", "scene.usdc"])
def test_v2_round_trip_is_exact_and_renders_identically(exported, tmp_path, layer):
    root, _ = exported
    import_usd(root / "usd" / layer, tmp_path / "back")
    original, back = load_scene(root / "scene"), load_scene(tmp_path / "back")
    assert back.version == 2 and back.objects[2].mesh is back.objects[3].mesh
    for a, b in zip(original.objects, back.objects, strict=True):
        assert (a.name, a.material, a.instance_id, a.emission_sides) == (
            b.name,
            b.material,
            b.instance_id,
            b.emission_sides,
        )
        assert np.array_equal(a.transform, b.transform), a.name
        for field in ("positions", "faces", "uvs"):
            assert np.array_equal(getattr(a.mesh, field), getattr(b.mesh, field)), (a.name, field)
    sets_a, sets_b = original.packing.unpack_atlas(original.maps), back.packing.unpack_atlas(back.maps)
    assert sets_a.keys() == sets_b.keys()
    for name in sets_a:
        for m in ("kd", "ks", "ka", "ke", "kw"):
            assert np.array_equal(getattr(sets_a[name], m), getattr(sets_b[name], m)), (name, m)
    assert np.array_equal(original.maps.kg, back.maps.kg)
    assert np.array_equal(_render(original), _render(back))


def test_an_object_moved_in_another_tool_comes_back_moved(exported, tmp_path):
    root, _ = exported
    stage = Usd.Stage.Open(str(root / "usd" / "scene.usda"))
    prim = stage.GetPrimAtPath("/Scene/Geometry/cube_b")
    moved = load_scene(root / "scene").objects[3].transform.copy()
    moved[:3, 3] += [0.1, 0.0, -0.25]
    UsdGeom.Xformable(prim).GetOrderedXformOps()[0].Set(Gf.Matrix4d(moved.T.tolist()))
    stage.GetRootLayer().Export(str(tmp_path / "edited.usda"))
    (tmp_path / "textures").symlink_to(root / "usd" / "textures")
    back = load_scene(import_usd(tmp_path / "edited.usda", tmp_path / "back") and tmp_path / "back")
    assert np.array_equal(back.objects[3].transform, moved)
    assert np.array_equal(back.objects[2].transform, load_scene(root / "scene").objects[2].transform)
