"""scene/packing.py: material sets laid into one atlas and cut out again, objects flattened."""

import numpy as np
import pytest
from testscenes import cube_mesh, rigid

from invrender.render.scene_buffers import atlas_lookup
from invrender.scene.packing import layout, pack_scene
from invrender.scene.types import Atlas, SceneError, SceneObject


def _sets(rng, shapes):
    out = {}
    for name, shape in shapes.items():
        atlas = Atlas.uniform(shape)
        atlas.kd[:] = rng.uniform(0, 1, (*shape, 3))
        atlas.ka[:] = rng.uniform(0.01, 1, shape)
        out[name] = atlas
    return out


SHAPES = {"a": (5, 7), "b": (16, 3), "c": (1, 1), "d": (4, 4)}


def test_rectangles_are_apart_by_the_padding_and_inside_the_atlas():
    packing = layout(SHAPES, padding=2)
    H, W = packing.shape
    owner = np.full((H, W), -1)
    for k, (name, rect) in enumerate(packing.rects.items()):
        assert (rect.height, rect.width) == SHAPES[name]
        grown = owner[
            max(rect.row - 2, 0) : rect.row + rect.height + 2, max(rect.col - 2, 0) : rect.col + rect.width + 2
        ]
        assert np.all(grown == -1), name  # nobody within 2 texels
        assert rect.row >= 2 and rect.col >= 2 and rect.row + rect.height + 2 <= H and rect.col + rect.width + 2 <= W
        owner[rect.row : rect.row + rect.height, rect.col : rect.col + rect.width] = k


def test_pack_then_unpack_gives_every_set_back_and_padding_repeats_its_edge():
    sets = _sets(np.random.default_rng(0), SHAPES)
    packing = layout(SHAPES)
    packed = packing.pack({n: a.kd for n, a in sets.items()})
    back = packing.unpack(packed)
    for name in SHAPES:
        assert np.array_equal(back[name], sets[name].kd)
        r = packing.rects[name]
        assert np.array_equal(packed[r.row - 1, r.col : r.col + r.width], sets[name].kd[0])  # the row above
        assert np.array_equal(packed[r.row : r.row + r.height, r.col + r.width], sets[name].kd[:, -1])
    unpacked = packing.unpack_atlas(packing.pack_atlas(sets))
    assert all(np.array_equal(unpacked[n].ka, sets[n].ka) for n in SHAPES)


def test_remapped_uvs_look_up_the_texel_the_set_would():
    sets = _sets(np.random.default_rng(1), SHAPES)
    packing = layout(SHAPES)
    packed = packing.pack_atlas(sets)
    uv = np.random.default_rng(2).uniform(0, 1, (2000, 2)).astype(np.float32)
    uv = np.concatenate([uv, [[0, 0], [1, 1], [0, 1], [1, 0]]]).astype(np.float32)  # the corners: clamped / padding
    for name in SHAPES:
        expected = atlas_lookup(sets[name].kd, uv)
        assert np.array_equal(atlas_lookup(packed.kd, packing.remap_uvs(uv, name)), expected), name


def test_one_set_is_packed_as_it_is():
    sets = _sets(np.random.default_rng(3), {"only": (6, 9)})
    mesh = cube_mesh()
    scene = pack_scene([SceneObject("cube", mesh, "only")], sets, np.zeros((6, 2, 2, 3), np.float32))
    assert scene.maps.atlas_shape == (6, 9) and np.array_equal(scene.maps.kd, sets["only"].kd)
    assert np.array_equal(scene.mesh.uvs, mesh.uvs) and np.array_equal(scene.mesh.positions, mesh.positions)
    assert scene.mesh.one_sided is None and np.all(scene.mesh.instance_ids == 0)


def test_flatten_transforms_concatenates_and_marks_ids_and_sides():
    sets = _sets(np.random.default_rng(4), {"p": (2, 3), "q": (3, 2)})
    cube = cube_mesh()
    T = rigid(30, (1.0, 0.5, -2.0))
    objects = [
        SceneObject("a", cube, "p", T, instance_id=7),
        SceneObject("b", cube, "q", np.diag([2.0, 2.0, 2.0, 1.0]), instance_id=9, emission_sides="one"),
    ]
    scene = pack_scene(objects, sets, np.zeros((6, 1, 1, 3), np.float32))
    n, f = len(cube.positions), len(cube.faces)
    assert np.allclose(scene.mesh.positions[:n], cube.positions @ T[:3, :3].T + T[:3, 3], atol=1e-6)
    assert np.array_equal(scene.mesh.positions[n:], 2 * cube.positions)
    assert np.array_equal(scene.mesh.faces, np.concatenate([cube.faces, cube.faces + n]))
    assert np.array_equal(scene.mesh.instance_ids, np.repeat([7, 9], f))
    assert np.array_equal(scene.mesh.one_sided, np.repeat([False, True], f))


@pytest.mark.parametrize(
    "edit, message",
    [
        (lambda o: o.__setattr__("material", "nope"), "objects[0].material: expected one of the material sets"),
        (
            lambda o: o.__setattr__("transform", np.diag([1.0, 1.0, -1.0, 1.0])),
            "objects[0].transform: expected a transform that keeps",
        ),
        (lambda o: o.__setattr__("transform", np.ones((3, 3))), "objects[0].transform: expected a row-major 4x4"),
        (lambda o: o.__setattr__("emission_sides", "both"), "objects[0].emission_sides: expected one of"),
    ],
)
def test_bad_objects_are_refused(edit, message):
    obj = SceneObject("a", cube_mesh(), "p")
    edit(obj)
    with pytest.raises(SceneError, match=message.replace("[", r"\[").replace("]", r"\]")):
        pack_scene([obj], _sets(np.random.default_rng(5), {"p": (2, 2)}), np.zeros((6, 1, 1, 3), np.float32))


def test_an_object_without_uvs_is_refused():
    mesh = cube_mesh()
    mesh.uvs = None
    with pytest.raises(SceneError, match=r"objects\[0\]\.mesh \(a\): vertex s,t"):
        pack_scene(
            [SceneObject("a", mesh, "p")],
            _sets(np.random.default_rng(6), {"p": (2, 2)}),
            np.zeros((6, 1, 1, 3), np.float32),
        )
