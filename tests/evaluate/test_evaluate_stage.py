"""The evaluate stage end to end on a small room: the truth recovered on another mesh and atlas
(maps ~0, views at their noise floor), training snapshots that improve, the spheres placed where
the held-out camera sees them, the figures, the CLI, and bad input refused before any work."""

import json

import numpy as np
import pytest
from truths import rebaked, small_room

from invrender.cli import main
from invrender.evaluate.stage import run
from invrender.evaluate.views import SPHERES
from invrender.scene.atomic import MARKER
from invrender.scene.cameras import project_points
from invrender.scene.format import write_scene
from invrender.scene.types import SceneError
from invrender.synthesize.capture import write_capture

HOLDOUT = "view_001.exr"
SPP = 8


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    root = tmp_path_factory.mktemp("evaluate")
    truth = small_room()
    write_capture(truth, {}, root / "capture", spp=SPP)
    recovered, texels = rebaked(truth)
    write_scene(root / "scene", recovered)
    texels.save(root / "atlas.npz")
    snapshots = root / "snapshots"
    snapshots.mkdir()
    maps = recovered.maps
    for iteration, error in ((0, 0.2), (50, 0.05), (100, 0.0)):  # written out of order on purpose
        np.savez(
            snapshots / f"iter_{iteration:06d}.npz",
            kd=np.clip(maps.kd + error, 0, 1),
            ks=maps.ks,
            ka=maps.ka,
            ke=maps.ke * (1 + 5 * error),
            kw=maps.kw,
            kg=maps.kg,
            iteration=iteration,
            wall_time=12.0 * iteration,
        )
    (snapshots / "notes.txt").write_text("not a snapshot\n")
    return {
        "root": root,
        "scene": root / "scene",
        "truth": root / "capture" / "ground_truth" / "scene",
        "atlas": root / "atlas.npz",
        "images": root / "capture" / "images",
        "snapshots": snapshots,
    }


@pytest.fixture(scope="module")
def evaluated(inputs):
    out = inputs["root"] / "report"
    doc = run(
        inputs["scene"],
        inputs["truth"],
        inputs["atlas"],
        inputs["images"],
        out,
        holdout=[HOLDOUT],
        snapshots_dir=inputs["snapshots"],
        spp=SPP,
        progress=False,
    )
    return out, doc


def test_it_writes_metrics_and_figures(evaluated):
    out, doc = evaluated
    assert json.loads((out / "metrics.json").read_text()) == doc
    names = {p.name for p in out.iterdir()}
    maps = {f"maps_{m}.png" for m in ("kd", "ks", "ka", "ke", "kw", "kg")}
    assert (
        names == {MARKER, "metrics.json", "accuracy_vs_time.png", "novel_view_001.png", "insertion_view_001.png"} | maps
    )
    assert set(doc) == {
        "version", "inputs", "paper", "tone_mapping", "psnr_cap_db", "maps", "novel_views", "insertion", "training"
    }  # fmt: skip
    assert doc["paper"]["insertion"] == {"psnr_db": 26.49, "ssim": 0.964, "ncc": 0.978, "mse": 0.002}


def test_the_truth_recovered_on_another_mesh_scores_near_zero_and_at_the_noise_floor(evaluated):
    doc = evaluated[1]
    assert doc["maps"]["light_maps_mse"] < 1e-5 and doc["maps"]["material_mse"] < 1e-5
    assert set(doc["maps"]["map_mse"]) == {"kd", "ks", "ka", "ke", "kw", "kg"}
    novel, inserted = doc["novel_views"], doc["insertion"]
    assert list(novel["views"]) == [HOLDOUT] and list(inserted["views"]) == [HOLDOUT]
    # the same scene: its renders score what the truth's own renders score, within the noise
    assert abs(novel["mean"]["psnr_db"] - novel["truth_floor"]["psnr_db"]) < 1.5, novel
    assert abs(inserted["mean"]["psnr_db"] - inserted["noise_floor"]["psnr_db"]) < 1.5, inserted
    assert 0 < inserted["mean"]["ssim"] < 1 and 0 < inserted["mean"]["ncc"] < 1


def test_the_spheres_sit_where_the_held_out_camera_sees_them(evaluated, inputs):
    spheres = evaluated[1]["insertion"]["spheres"]
    assert [s["kind"] for s in spheres] == list(SPHERES) and evaluated[1]["insertion"]["placement"] == "automatic"
    from invrender.scene.format import load_scene

    camera = next(c for c in load_scene(inputs["scene"]).cameras if c.name == HOLDOUT)
    centres = np.array([s["center"] for s in spheres])
    pixels = project_points(camera, centres)
    assert np.all((pixels >= 0) & (pixels < [camera.width, camera.height])), pixels
    distance = np.linalg.norm(centres - camera.center, axis=1)
    assert np.all(distance > 3 * np.array([s["radius"] for s in spheres]))
    assert len({tuple(np.round(c, 3)) for c in centres}) == 3


def test_snapshots_make_a_table_in_iteration_order_that_improves(evaluated):
    table = evaluated[1]["training"]
    assert [row["iteration"] for row in table] == [0, 50, 100]
    assert [row["wall_time_s"] for row in table] == [0.0, 600.0, 1200.0]
    light = [row["light_maps_mse"] for row in table]
    material = [row["material_mse"] for row in table]
    assert light[0] > light[1] > light[2] and material[0] > material[1] > material[2]
    assert table[2]["material_mse"] == pytest.approx(evaluated[1]["maps"]["material_mse"])
    psnr = [row["novel_view_psnr_db"] for row in table]
    assert psnr[0] < psnr[2] and all(row["novel_view_spp"] == 4 for row in table)


def test_a_given_placement_is_used_and_the_cli_runs_the_stage(inputs, tmp_path):
    spheres = [
        {"kind": "diffuse", "center": [0.0, 0.5, 0.0], "radius": 0.2},
        {"kind": "emitting", "center": [0.5, 0.5, 0.3], "radius": 0.1},
    ]
    common = (inputs["scene"], inputs["truth"], inputs["atlas"], inputs["images"])
    doc = run(*common, tmp_path / "given", spp=2, placement=spheres, progress=False)
    assert doc["insertion"]["placement"] == "given" and doc["novel_views"] is None and doc["training"] is None
    assert [s["center"] for s in doc["insertion"]["spheres"]] == [s["center"] for s in spheres]
    assert list(doc["insertion"]["views"]) == ["view_000.exr", "view_001.exr"]  # no hold-out: every camera
    args = ["evaluate", "--scene", inputs["scene"], "--truth", inputs["truth"], "--atlas", inputs["atlas"]]
    args += ["--images", inputs["images"], "--out", tmp_path / "cli", "--holdout", HOLDOUT, "--spp", "2"]
    args += ["--sphere", "specular", "0.1", "0.4", "0.2", "0.15"]
    assert main([str(a) for a in args]) == 0
    written = json.loads((tmp_path / "cli" / "metrics.json").read_text())
    assert written["inputs"]["holdout"] == [HOLDOUT] and written["insertion"]["placement"] == "given"
    assert written["insertion"]["spheres"] == [
        {"kind": "specular", "material": SPHERES["specular"], "center": [0.1, 0.4, 0.2], "radius": 0.15}
    ]


def test_bad_input_is_refused_before_any_work(inputs, tmp_path, capsys):
    common = (inputs["scene"], inputs["truth"], inputs["atlas"], inputs["images"])
    with pytest.raises(SceneError, match="a camera named nowhere.exr"):
        run(*common, tmp_path / "a", holdout=["nowhere.exr"])
    broken = tmp_path / "snapshots"
    broken.mkdir()
    np.savez(broken / "iter_000001.npz", kd=np.zeros((4, 4, 3)))
    with pytest.raises(SceneError, match="iter_000001.npz: ks, ka, ke, kw, kg, iteration, wall_time"):
        run(*common, tmp_path / "b", snapshots_dir=broken)
    with pytest.raises(SceneError, match="evaluate placement: \\[0\\].kind"):
        run(*common, tmp_path / "c", placement=[{"kind": "glass", "center": [0, 0, 0], "radius": 1}])
    other_atlas = tmp_path / "atlas.npz"
    from invrender.scene.atlas import AtlasTexels

    texels = AtlasTexels.load(inputs["atlas"])
    AtlasTexels(
        *(a[:-1] for a in (texels.triangle, texels.barycentric, texels.position, texels.normal, texels.mask))
    ).save(other_atlas)
    args = ["evaluate", "--scene", inputs["scene"], "--truth", inputs["truth"], "--atlas", other_atlas]
    assert main([str(a) for a in [*args, "--images", inputs["images"], "--out", tmp_path / "d"]]) == 2
    assert "shape: expected the recovered scene's atlas size" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["atlas.npz", "snapshots"]  # nothing written
