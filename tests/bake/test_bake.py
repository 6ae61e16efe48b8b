"""bake: recovered maps + the geometry stage's mesh + the capture's cameras -> a scene directory
that renders exactly as the same Scene built in memory."""

import numpy as np
import pytest

from invrender.cli import main
from invrender.render.features import Features
from invrender.render.renderer import Renderer
from invrender.scene.atlas import rasterize_atlas
from invrender.scene.cameras import write_colmap
from invrender.scene.format import load_scene
from invrender.scene.mesh_io import write_ply
from invrender.scene.snapshots import write_snapshot
from invrender.scene.types import Maps, Scene


@pytest.fixture
def recovered(tmp_path):
    from testscenes import box_room

    truth = box_room(window=True, ks=0.3, ka=0.05)
    (tmp_path / "geometry").mkdir()
    write_ply(tmp_path / "geometry" / "mesh.ply", truth.mesh)
    rasterize_atlas(truth.mesh, *truth.maps.atlas_shape).save(tmp_path / "geometry" / "atlas.npz")
    write_colmap(tmp_path / "cameras", truth.cameras)
    write_snapshot(tmp_path / "maps.npz", truth.maps, iteration=7, wall_time=1.5)
    return tmp_path, truth


def test_bake_writes_the_scene_the_maps_describe(recovered):
    root, truth = recovered
    assert (
        main(
            [
                "bake",
                "--maps",
                str(root / "maps.npz"),
                "--geometry",
                str(root / "geometry"),
                "--cameras",
                str(root / "cameras"),
                "--out",
                str(root / "scene"),
            ]
        )
        == 0
    )  # noqa: E501
    baked = load_scene(root / "scene")
    for name in ("kd", "ks", "ka", "ke", "kw", "kg"):
        np.testing.assert_array_equal(getattr(baked.maps, name), getattr(truth.maps, name), err_msg=name)
    np.testing.assert_array_equal(baked.mesh.faces, truth.mesh.faces)
    assert [c.name for c in baked.cameras] == [c.name for c in truth.cameras]
    features = Features(one_sided=False, max_bounces=3)
    camera = truth.cameras[0]
    ours = Renderer(baked, features).render(camera, spp=4, aovs=False)["radiance"]
    memory = Renderer(Scene(truth.mesh, truth.maps, truth.cameras), features).render(camera, spp=4, aovs=False)
    np.testing.assert_array_equal(ours, memory["radiance"])
    metadata = __import__("json").loads((root / "scene" / "scene.json").read_text())["metadata"]
    assert metadata["iteration"] == 7 and metadata["training_seconds"] == 1.5


def test_maps_of_another_atlas_are_refused(recovered, capsys):
    root, truth = recovered
    small = Maps.uniform(size=(8, 8), cube=4)
    write_snapshot(root / "small.npz", small, iteration=1, wall_time=0.0)
    assert (
        main(
            [
                "bake",
                "--maps",
                str(root / "small.npz"),
                "--geometry",
                str(root / "geometry"),
                "--cameras",
                str(root / "cameras"),
                "--out",
                str(root / "scene"),
            ]
        )
        == 2
    )  # noqa: E501
    h, w = truth.maps.atlas_shape
    assert (
        f"small.npz: kd: expected shape ({h}, {w}, 3) (the recovered atlas), got (8, 8, 3)" in capsys.readouterr().err
    )
    assert not (root / "scene").exists()
