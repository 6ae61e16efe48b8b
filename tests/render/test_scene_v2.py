"""A v2 scene (objects with transforms, material sets, one cube instanced twice) renders like the
same geometry flattened into v1 by hand, and its gradients land in each set's own texels.

The reference (testscenes.flattened_by_hand) lays the sets side by side without padding and
transforms the positions itself: only the texels and the world-space triangles agree with
scene/packing.py, so equal renders and equal gradients per set say that packing kept both."""

import numpy as np
import pytest
from testscenes import flattened_by_hand, three_objects

from invrender.render.adjoint import backward
from invrender.render.features import Features
from invrender.render.renderer import Renderer, pixel_requests
from invrender.scene.format import load_scene, write_scene
from invrender.scene.packing import pack_scene

SPP, SEED = 16, 5
ATLAS = ("kd", "ks", "ka", "ke", "kw")


@pytest.fixture(scope="module")
def scenes(tmp_path_factory):
    objects, materials, kg, cameras = three_objects()
    directory = tmp_path_factory.mktemp("v2") / "scene"
    write_scene(directory, pack_scene(objects, materials, kg, cameras))
    v2 = load_scene(directory)  # through the files: the format's round trip is part of the claim
    v1, columns = flattened_by_hand(objects, materials, kg, cameras)
    return v2, v1, columns, materials


def _reference_set(v1_maps, columns, materials, name, grads):
    """A set's texels cut out of the by-hand layout (maps or gradient maps)."""
    h, w = materials[name].atlas_shape
    c = columns[name]
    return {m: np.asarray(grads[m])[:h, c : c + w] for m in ATLAS}


def test_v2_renders_like_its_flattening_into_v1(scenes):
    v2, v1, _, _ = scenes
    assert v2.version == 2 and [o.name for o in v2.objects] == ["room", "table", "cube_a", "cube_b"]
    assert v2.objects[2].mesh is v2.objects[3].mesh  # one mesh file, two placements
    features = Features.everything(max_bounces=3)
    camera = v2.cameras[0]
    a = Renderer(v2, features).render(camera, spp=SPP, seed=SEED)
    b = Renderer(v1, features).render(camera, spp=SPP, seed=SEED)
    assert a["dropped"] == b["dropped"] == 0
    np.testing.assert_allclose(a["radiance"], b["radiance"], rtol=1e-6, atol=0)  # measured: identical
    assert np.array_equal(a["instance_id"], b["instance_id"])
    assert set(np.unique(a["instance_id"])) == {1, 2, 3, 4}  # every object in view
    assert a["radiance"].mean() > 0.05


def test_gradients_land_in_each_material_sets_own_texels(scenes):
    v2, v1, columns, materials = scenes
    features = Features.everything(max_bounces=3)
    camera = v2.cameras[0]
    requests = pixel_requests(camera)
    adjoint = np.random.default_rng(1).uniform(0.5, 1.5, (len(requests), 3)).astype(np.float32)
    packed = backward(Renderer(v2, features), [camera], requests, adjoint, SPP, seed=SEED)
    reference = backward(Renderer(v1, features), [camera], requests, adjoint, SPP, seed=SEED)
    per_set = v2.packing.unpack_atlas(packed)
    for name in materials:
        expected = _reference_set(v1.maps, columns, materials, name, reference)
        for m in ATLAS:
            np.testing.assert_allclose(
                getattr(per_set[name], m), expected[m], rtol=1e-6, atol=1e-12, err_msg=f"{name}.{m}"
            )
        assert np.abs(per_set[name].kd).sum() > 0, name
    outside = np.ones(v2.maps.atlas_shape, bool)  # padding and unused texels: no lookup lands there
    for rect in v2.packing.rects.values():
        outside[rect.row : rect.row + rect.height, rect.col : rect.col + rect.width] = False
    for m in ATLAS:
        assert not np.any(packed[m][outside]), m


def _inside(mask: np.ndarray) -> np.ndarray:
    """Pixels whose 8 neighbours are in the mask too: every jittered sample of them lands inside."""
    padded = np.pad(mask, 1)
    h, w = mask.shape
    return np.all([padded[1 + dy : 1 + dy + h, 1 + dx : 1 + dx + w] for dy in (-1, 0, 1) for dx in (-1, 0, 1)], axis=0)


def test_the_instanced_set_gets_the_sum_of_both_copies(scenes):
    """Direct light only (1 bounce): a loss on the cubes' pixels moves the cubes' kd and the
    light's ke, no other set's kd; each copy's share lands in the one 'paint' set, and the
    loss on both copies gets the sum of the two shares."""
    v2 = scenes[0]
    features = Features.everything(max_bounces=1)
    camera = v2.cameras[0]
    requests = pixel_requests(camera)
    renderer = Renderer(v2, features)
    instance = renderer.aovs([camera], requests)["instance_id"].reshape(camera.height, camera.width)
    grads = {}
    for label, ids in (("a", [3]), ("b", [4]), ("both", [3, 4])):
        adjoint = np.where(_inside(np.isin(instance, ids)).reshape(-1, 1), 1.0, 0.0).astype(np.float32)
        grads[label] = v2.packing.unpack_atlas(backward(renderer, [camera], requests, adjoint, SPP, seed=SEED))
    for label in ("a", "b"):
        assert grads[label]["paint"].kd.sum() > 0, label
        assert not np.any(grads[label]["walls"].kd) and not np.any(grads[label]["wood"].kd), label
        assert np.abs(grads[label]["walls"].ke).sum() > 0, label  # the light it is lit by
    np.testing.assert_allclose(grads["both"]["paint"].kd, grads["a"]["paint"].kd + grads["b"]["paint"].kd, rtol=1e-5)
