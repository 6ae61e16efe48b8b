"""The milo stage end to end on a tiny capture: its chain rule against autograd through the
renderer's torch operation, resume after SIGKILL bit for bit, and the refusals."""

import numpy as np
import pytest
import torch
from milo_capture import TINY, assert_same_weights, kill_at_first_checkpoint, milo_args, training_on

from invrender.cli import main
from invrender.milo import checkpoint
from invrender.milo.config import resolve
from invrender.milo.train import iteration_seed
from invrender.render.adjoint import GRAD_CHANNELS
from invrender.render.batches import ray_batch
from invrender.render.torch_ops import render_rays
from invrender.scene.cameras import read_cameras, write_colmap
from invrender.scene.images import read_image, write_exr

NO_PRIORS = {"beta": 0.0, "theta": 0.0, "zeta": 0.0, "l2": 0.0, "smoothness": 0.0, "sky_smoothness": 0.0}
NO_STEPS = {"lr_mlp": 0.0, "lr_template": 0.0, "lr_texels": 0.0}


@pytest.mark.parametrize("model", ["network", "texels"])
def test_sparse_chain_rule_equals_autograd_through_the_renderer(tiny_capture, model):
    """The stage evaluates the model with gradients only on the texels the adjoint reached;
    the reference scatters the model's maps over the whole atlas and back-propagates through
    RenderRays (render/torch_ops.py), the same forward and backward samples."""
    settings = resolve("demo", {**TINY, **NO_PRIORS, **NO_STEPS, "specular_prior": 0.0, "model": model})
    training = training_on(tiny_capture, settings)
    training.step()
    ours = [p.grad.clone() for p in training.net.parameters()]

    training.net.zero_grad(set_to_none=True)
    t, views = training.texels, training.views
    requests = ray_batch(views.cameras, settings["rays"], settings["seed"], 0)
    out = training.net.texel_surface(t, None)["maps"]
    flat = torch.zeros(t.shape[0] * t.shape[1], out.shape[1]).index_put(
        (torch.from_numpy(t.rows * t.shape[1] + t.cols),), out
    )
    atlas = flat.reshape(*t.shape, -1)
    maps = {
        name: atlas[..., c].squeeze(-1) if c.stop - c.start == 1 else atlas[..., c] for name, c in GRAD_CHANNELS.items()
    }
    n = settings["sky_resolution"]
    maps["kg"] = training.net.sky(training.directions).reshape(6, n, n, 3)
    radiance = render_rays(
        maps, training.renderer, views.cameras, requests, settings["spp"], iteration_seed(settings["seed"], 0)
    )
    target = torch.from_numpy(views.pixels[requests[:, 3]])
    ((radiance - target) ** 2).sum(1).mean().backward()
    reference = [p.grad for p in training.net.parameters()]
    for mine, theirs in zip(ours, reference):
        np.testing.assert_allclose(mine.numpy(), theirs.numpy(), rtol=2e-4, atol=1e-7 * float(theirs.abs().max()))
    assert any(float(g.abs().max()) > 0 for g in reference)


def _weights(path):
    return torch.load(path, weights_only=False)["network"]


def test_resume_after_sigkill_gives_the_same_weights(tiny_capture, tmp_path):
    # killed at its first checkpoint (4), resumed across four more and a snapshot
    settings = {**TINY, "iterations": 20, "checkpoint_every": 4, "snapshot_every": 10}
    assert main(milo_args(tiny_capture, tmp_path / "straight", settings)) == 0

    killed = tmp_path / "killed"
    kill_at_first_checkpoint(milo_args(tiny_capture, killed, settings), killed)
    assert main(milo_args(tiny_capture, killed, settings, "--resume", "always")) == 0
    assert_same_weights(tmp_path / "straight" / "weights.pt", killed / "weights.pt")
    rows = (killed / "log.csv").read_text().splitlines()
    assert [int(r.split(",")[0]) for r in rows[1:]] == list(range(1, 21))  # the killed run's extra rows dropped


def test_a_different_seed_gives_different_weights(tiny_capture, tmp_path):
    assert main(milo_args(tiny_capture, tmp_path / "a", TINY)) == 0
    assert main(milo_args(tiny_capture, tmp_path / "b", {**TINY, "seed": 1})) == 0
    a, b = _weights(tmp_path / "a" / "weights.pt"), _weights(tmp_path / "b" / "weights.pt")
    assert any(not torch.equal(a[k], b[k]) for k in a)


def _last_line(capsys):
    return capsys.readouterr().err.strip().splitlines()[-1]


def test_corrupt_or_mismatched_checkpoints_are_refused(tiny_capture, tmp_path, capsys):
    out = tmp_path / "run"
    settings = {**TINY, "iterations": 7, "checkpoint_every": 3}
    assert main(milo_args(tiny_capture, out, settings)) == 0
    saved = checkpoint.latest(out / "checkpoints")  # the newest only
    assert checkpoint.checkpoints(out / "checkpoints") == [saved] and saved.name == "iter_000006.pt"

    assert main(milo_args(tiny_capture, out, {**settings, "lr_mlp": 0.01}, "--resume", "always")) == 2
    assert (
        f"{saved}: settings: expected the settings of this run; it was made with other values of lr_mlp"
        in _last_line(capsys)
    )
    saved.write_bytes(saved.read_bytes()[:100])
    assert main(milo_args(tiny_capture, out, settings, "--resume", "always")) == 2
    assert f"{saved}: checkpoint: expected a checkpoint written by invrender milo (unreadable" in _last_line(capsys)


def test_a_checkpoint_of_another_atlas_is_refused(tmp_path):
    settings = resolve("demo")
    state = {"iteration": 1, "settings": settings, "settings_hash": "s", "atlas_hash": "a"}
    path = checkpoint.save(tmp_path, state)
    with pytest.raises(Exception, match="atlas: expected the atlas of this run"):
        checkpoint.load(path, settings, "s", "b")


def _copy_capture(root, tmp_path):
    import shutil

    shutil.copytree(root / "cameras", tmp_path / "cameras")
    return tmp_path / "cameras"


def test_bad_captures_stop_before_training_naming_the_file(tiny_capture, tmp_path, capsys):
    cameras = _copy_capture(tiny_capture, tmp_path)
    model = cameras
    run = lambda: main(
        [
            "milo",
            "--geometry",
            str(tiny_capture / "geometry"),
            "--cameras",
            str(model),
            "--images",
            str(cameras / "images"),
            "--out",
            str(tmp_path / "out"),
            "--set",
            "iterations=1",
        ]
    )  # noqa: E731

    image = cameras / "images" / "view_001.exr"
    pixels = read_image(image)
    image.unlink()  # a hard link into the capture: replace it, do not write through it
    bad = pixels.copy()
    bad[3, 4, 1] = np.nan
    write_exr(image, bad)
    assert run() == 2
    line = _last_line(capsys)
    assert str(image) in line and "expected finite values" in line

    image.unlink()
    write_exr(image, pixels[:, :-2])
    assert run() == 2
    assert f"{image}: size: expected 32 x 24 as its camera says, got 30 x 24" in _last_line(capsys)

    image.unlink()
    write_exr(image, pixels)
    views = read_cameras(cameras)
    views[2].t = views[2].t + np.array([0.0, 0.0, -100.0])  # 100 m behind its own back: sees nothing
    model = tmp_path / "moved"
    write_colmap(model, views)
    assert run() == 2
    assert f"{model}: camera view_002.exr: expected a camera that sees the mesh" in _last_line(capsys)
    assert not (tmp_path / "out" / "weights.pt").exists()


def test_a_fresh_run_keeps_no_snapshots_of_an_earlier_longer_one(tiny_capture, tmp_path):
    out = tmp_path / "run"
    assert main(milo_args(tiny_capture, out, {**TINY, "iterations": 7, "snapshot_every": 3})) == 0
    assert sorted(p.name for p in (out / "snapshots").iterdir()) == [f"iter_00000{i}.npz" for i in (3, 6, 7)]
    assert main(milo_args(tiny_capture, out, {**TINY, "iterations": 4, "snapshot_every": 3})) == 0
    assert sorted(p.name for p in (out / "snapshots").iterdir()) == ["iter_000003.npz", "iter_000004.npz"]
