"""The material stage on small synthetic captures with the TRUE poses and mesh (material_capture.py):
the shared albedo recovered on the surface, more copies giving a better one, resume, the support
plane, multi-image pooling, bake --material, and the refusals."""

from __future__ import annotations

import csv
import dataclasses
import json
import shutil

import numpy as np
import pytest
from material_capture import kd_rmse, truth_kd

from invrender.bake import duplicates as bake
from invrender.cli import main
from invrender.duplicates_material import stage
from invrender.duplicates_material.support import support_plane
from invrender.scene.atlas import AtlasTexels
from invrender.scene.cameras import read_cameras, write_colmap
from invrender.scene.format import load_scene
from invrender.scene.images import read_mask, write_mask
from invrender.scene.mesh_io import read_mesh
from invrender.scene.poses import placements, read_poses

# Starting from grey under the (known) white sky; 30 iterations of 4096 rays at 2 spp.
TRAINING = {
    "start": "grey",
    "iterations": 30,
    "rays": 4096,
    "spp": 2,
    "sky_resolution": 4,
    "lr": 0.2,
    "lr_sky": 0.02,
    "snapshot_every": 30,
    "support_resolution": 32,
    "figure_spp": 2,
}


def face_means(kd: np.ndarray, texels: AtlasTexels, parts) -> np.ndarray:
    """The mean kd of each side of the box (the print averaged out: what a photograph of
    ~300 pixels per copy can tell at any texel resolution)."""
    return np.array([kd[texels.mask & (texels.triangle >= a) & (texels.triangle < b)].mean(0) for a, b in parts])


def albedo_errors(capture, inputs, out) -> dict:
    """kd errors of the start (iteration 0) and the result: per texel (RMSE over the object's
    texels) and per side (mean absolute error of the sides' mean colours)."""
    texels = AtlasTexels.load(inputs["geometry_dir"] / "atlas.npz")
    meta = json.loads((capture / "ground_truth" / "scene" / "scene.json").read_text())["metadata"]
    parts = [p["faces"] for p in meta["object"]["parts"]]
    truth = face_means(truth_kd(capture), texels, parts)
    errors = {}
    for name, path in (("start", out / "snapshots" / "iter_000000.npz"), ("end", out / "maps.npz")):
        kd = np.load(path)["kd"]
        errors[name] = {
            "texels": kd_rmse(kd, capture, texels.mask),
            "sides": float(np.abs(face_means(kd, texels, parts) - truth).mean()),
        }
    return errors


@pytest.fixture(scope="module")
def six(captures, tmp_path_factory):
    capture, inputs = captures[6]
    out = tmp_path_factory.mktemp("six") / "material"
    summary = stage.run(**inputs, out_dir=out, preset="ci", overrides=TRAINING, progress=False)
    return capture, inputs, out, summary


def test_the_shared_albedo_approaches_the_truth_on_the_surface(six):
    """Six copies, the true poses and mesh: from grey (side colours 0.2 off on average) to within
    0.05 of the truth per side, the per-texel error down by a third (what is left is the prints'
    detail, finer than the ~10 pixels a side covers in the photograph)."""
    capture, inputs, out, summary = six
    errors = albedo_errors(capture, inputs, out)
    assert errors["start"]["sides"] > 0.15
    assert errors["end"]["sides"] < 0.05
    assert errors["end"]["texels"] < 0.75 * errors["start"]["texels"]
    # the outputs, and what training.json says about the run
    for name in ("maps.npz", "support/mesh.ply", "support/maps.npz", "figure.png", "training.json"):
        assert (out / name).is_file(), name
    with open(out / "log.csv", newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert [int(r["iteration"]) for r in rows] == list(range(1, 31))
    assert summary["iterations"] == 30 and summary["copies"] == 6 and summary["peak_memory_mb"] > 0
    assert summary["pixels"]["object"] == int((read_mask(inputs["masks_path"]) > 0).sum())


def test_more_copies_give_a_better_albedo(six, captures, tmp_path):
    """The paper's claim (Table 2), measured: two copies of the same box under the same light and
    the same training budget recover its albedo worse than six (they show fewer of its sides, and
    each side from fewer directions)."""
    capture6, inputs6, out6, _ = six
    capture2, inputs2 = captures[2]
    stage.run(**inputs2, out_dir=tmp_path / "two", preset="ci", overrides=TRAINING, progress=False)
    two = albedo_errors(capture2, inputs2, tmp_path / "two")["end"]
    six_ = albedo_errors(capture6, inputs6, out6)["end"]
    assert six_["texels"] < 0.9 * two["texels"], (six_, two)
    assert six_["sides"] < two["sides"], (six_, two)


def test_a_resumed_run_ends_where_an_uninterrupted_one_does(captures, tmp_path):
    _, inputs = captures[2]
    settings = {**TRAINING, "iterations": 4, "rays": 512, "checkpoint_every": 2}
    stage.run(**inputs, out_dir=tmp_path / "straight", preset="ci", overrides=settings, progress=False)
    stopped = tmp_path / "stopped"
    stage.run(**inputs, out_dir=stopped, preset="ci", overrides=settings, progress=False)
    assert sorted(p.name for p in (stopped / "checkpoints").iterdir()) == ["iter_000002.pt"]
    (stopped / "maps.npz").unlink()  # as if killed after iteration 2's checkpoint
    stage.run(**inputs, out_dir=stopped, preset="ci", overrides=settings, resume="always", progress=False)
    straight, resumed = np.load(tmp_path / "straight" / "maps.npz"), np.load(stopped / "maps.npz")
    for key in ("kd", "ks", "ka", "kg"):
        assert np.array_equal(straight[key], resumed[key]), key
    with open(stopped / "log.csv", newline="") as handle:
        assert [int(r["iteration"]) for r in csv.DictReader(handle)] == [1, 2, 3, 4]


def test_the_support_plane_is_the_floor_the_copies_stand_on(captures):
    """From the poses alone: the floor is y = 0 with normal +y; the copies rest 0-2 mm above it."""
    capture, inputs = captures[6]
    mesh = read_mesh(inputs["geometry_dir"] / "mesh.ply")
    copies = placements(read_poses(inputs["poses_path"]), mesh, "object")
    worlds = [c.mesh.positions.astype(np.float64) @ c.transform[:3, :3].T + c.transform[:3, 3] for c in copies]
    tilted_up = np.array([0.3, 1.0, -0.4])  # a camera's up direction is only a start
    normal, offset = support_plane(worlds, tilted_up / np.linalg.norm(tilted_up))
    assert np.degrees(np.arccos(min(normal[1], 1.0))) < 0.5
    assert 0.0 <= offset <= 0.0025


def test_texels_no_photograph_shows_keep_their_start(captures, tmp_path):
    """Light bounces off texels the photograph does not show (the floor behind each copy, the
    copies' undersides) onto pixels it does show, but their gradient must not train them: they
    would soak up the residuals (the floor behind each copy took the copy's colours, ghosts once
    the copies move). With the regularisers that act on kd off, each ends at its grey start
    exactly, and the seen ones have moved."""
    from invrender.duplicates_material.support import support_texels
    from invrender.scene.first_guess import seen_texels

    _, inputs = captures[6]
    out = tmp_path / "material"
    settings = {**TRAINING, "iterations": 8, "smoothness": 0.0}
    stage.run(**inputs, out_dir=out, preset="ci", overrides=settings, progress=False)
    ids = read_mask(inputs["masks_path"])
    (camera,) = read_cameras(inputs["cameras_path"])
    texels = AtlasTexels.load(inputs["geometry_dir"] / "atlas.npz")
    poses = {
        c.instance_id: c.transform
        for c in placements(read_poses(inputs["poses_path"]), read_mesh(inputs["geometry_dir"] / "mesh.ply"), "object")
    }
    quad = support_texels(read_mesh(out / "support" / "mesh.ply", require_uvs=False), TRAINING["support_resolution"])
    for kd, atlas, seen in (
        (np.load(out / "maps.npz")["kd"], texels, seen_texels(texels, poses, camera, ids)),
        (np.load(out / "support" / "maps.npz")["kd"], quad, seen_texels(quad, {0: np.eye(4)}, camera, ids)),
    ):
        unseen = atlas.mask & ~seen
        assert unseen.sum() > 20 and seen.sum() > 20
        assert np.abs(kd[unseen] - 0.5).max() < 1e-6, np.abs(kd[unseen] - 0.5).max()
        assert np.abs(kd[seen] - 0.5).mean() > 0.02


def test_images_without_a_mask_give_the_pixels_that_meet_the_objects(captures, tmp_path):
    """Two photographs of the pile (here: the same one twice, under two names): the second has no
    mask, so its object pixels are those whose primary ray meets a copy, about as many as the
    first's mask holds; both images' rays are pooled."""
    _, inputs = captures[6]
    cameras_dir = tmp_path / "cameras"
    (camera,) = read_cameras(inputs["cameras_path"])
    second = dataclasses.replace(camera, name="view_001.exr")
    write_colmap(cameras_dir, [camera, second])
    shutil.copytree(inputs["cameras_path"] / "images", cameras_dir / "images")
    shutil.copy(cameras_dir / "images" / "view_000.exr", cameras_dir / "images" / "view_001.exr")
    settings = {**TRAINING, "iterations": 1, "rays": 256}
    summary = stage.run(
        **{**inputs, "cameras_path": cameras_dir},
        out_dir=tmp_path / "out",
        preset="ci",
        overrides=settings,
        progress=False,
    )
    masked = int((read_mask(inputs["masks_path"]) > 0).sum())
    assert abs(summary["pixels"]["object"] - 2 * masked) < 0.05 * masked, (summary["pixels"], masked)


def test_bake_writes_the_recovered_material_support_and_sky(six, tmp_path):
    capture, inputs, out, _ = six
    bake.run(inputs["geometry_dir"], inputs["poses_path"], inputs["cameras_path"], None, tmp_path / "scene", out)
    scene = load_scene(tmp_path / "scene")
    assert sorted(o.material for o in scene.objects) == ["object"] * 6 + ["support"]
    sets = scene.packing.unpack_atlas(scene.maps)
    recovered = np.load(out / "maps.npz")
    assert np.allclose(sets["object"].kd, recovered["kd"], atol=1e-3)  # EXR half floats
    assert np.allclose(sets["support"].kd, np.load(out / "support" / "maps.npz")["kd"], atol=1e-3)
    assert np.allclose(scene.maps.kg, recovered["kg"], rtol=1e-3)


def _args(inputs, out, masks):
    return [
        "duplicates-material",
        "--geometry", str(inputs["geometry_dir"]),
        "--poses", str(inputs["poses_path"]),
        "--cameras", str(inputs["cameras_path"]),
        "--masks", str(masks),
        "--out", str(out),
    ]  # fmt: skip


@pytest.mark.parametrize("kept", [3, 0], ids=["objects-under-1-percent", "environment-only"])
def test_too_few_object_pixels_stop_before_anything_is_written(captures, tmp_path, capsys, kept):
    """Copies covering under 1 % of the pixels (a few pixels of one copy kept), or none at all:
    one message naming the mask, the field and what was expected; no output directory."""
    _, inputs = captures[6]
    ids = read_mask(inputs["masks_path"])
    ys, xs = np.nonzero(ids == 1)
    small = np.zeros_like(ids)
    small[ys[:kept], xs[:kept]] = 1
    masks = tmp_path / "view_000.png"
    write_mask(masks, small)
    assert main(_args(inputs, tmp_path / "out", masks)) == 2
    message = capsys.readouterr().err.strip().splitlines()[-1]
    share = f"{kept / ids.size:.2%}"
    assert (
        f"{masks}: instances: expected registered copies covering at least 1% of the image's pixels, got {share}"
        in message
    )
    assert not (tmp_path / "out").exists()


def test_without_a_support_only_object_pixels_train(captures, tmp_path):
    """`support: none`: no quad, no support material, every ray from the copies' masks."""
    _, inputs = captures[2]
    settings = {**TRAINING, "iterations": 1, "rays": 256, "support": "none"}
    summary = stage.run(**inputs, out_dir=tmp_path / "out", preset="ci", overrides=settings, progress=False)
    assert summary["support"] is None and summary["pixels"]["support"] == 0
    assert not (tmp_path / "out" / "support").exists()
    with open(tmp_path / "out" / "log.csv", newline="") as handle:
        (row,) = csv.DictReader(handle)
    assert (int(row["rays_object"]), int(row["rays_support"])) == (256, 0)


def test_poses_without_a_registered_copy_are_refused(captures, tmp_path, capsys):
    _, inputs = captures[2]
    doc = json.loads(inputs["poses_path"].read_text())
    for entry in doc["instances"]:
        entry["registered"] = False
    poses = tmp_path / "poses.json"
    poses.write_text(json.dumps(doc))
    args = _args({**inputs, "poses_path": poses}, tmp_path / "out", inputs["masks_path"])
    assert main(args) == 2
    message = capsys.readouterr().err.strip().splitlines()[-1]
    assert f"{poses}: instances: expected at least one registered copy (registered: true)" in message
    assert not (tmp_path / "out").exists()
