"""The render stage through the CLI, on a scene directory written to disk."""

import numpy as np
import OpenEXR

from invrender.cli import main
from invrender.scene.images import read_image


def test_render_stage_writes_radiance_previews_and_exact_id_aovs(stage_scene_dir, tmp_path):
    out = tmp_path / "renders"
    assert main(["render", str(stage_scene_dir), "--out", str(out), "--spp", "4"]) == 0
    radiance = read_image(out / "view.exr")
    assert radiance.shape == (24, 32, 3) and np.isfinite(radiance).all() and radiance.mean() > 0
    assert (out / "view.png").stat().st_size > 100
    ids = OpenEXR.File(str(out / "aovs" / "view_triangle.exr")).channels()["Y"].pixels
    assert ids.dtype == np.uint32 and ids.min() >= 1 and ids.max() <= 18  # every pixel hits the closed room
    depth = read_image(out / "aovs" / "view_depth.exr")[..., 0]
    assert np.all((depth > 0.05) & (depth < 6.0))


def test_render_stage_names_a_missing_camera_and_writes_nothing(stage_scene_dir, tmp_path, capsys):
    out = tmp_path / "renders"
    assert main(["render", str(stage_scene_dir), "--out", str(out), "--camera", "nope"]) == 2
    assert (
        capsys.readouterr()
        .err.strip()
        .endswith(
            f"{stage_scene_dir / 'scene.json'}: cameras: expected a camera named nope "
            "(--camera); the scene has view.exr"
        )
    )
    assert not out.exists()


def test_variance_beside_each_view_predicts_the_spread_between_two_seeds(stage_scene_dir, tmp_path):
    """The variance written per pixel is the error bar of that pixel's mean: two independent
    renders differ by (a - b)^2 ~ var_a + var_b on average over the image."""
    renders = []
    for seed in (1, 2):
        out = tmp_path / f"seed{seed}"
        assert main(["render", str(stage_scene_dir), "--out", str(out), "--spp", "8", "--seed", str(seed)]) == 0
        renders.append((read_image(out / "view.exr"), read_image(out / "aovs" / "view_variance.exr")))
    (a, var_a), (b, var_b) = renders
    assert var_a.shape == a.shape and np.all(var_a >= 0) and var_a.max() > 0
    ratio = ((a - b) ** 2).mean() / (var_a + var_b).mean()
    assert 0.7 < ratio < 1.3, ratio


def test_max_bounces_and_feature_overrides_without_a_features_file(stage_scene_dir, tmp_path):
    full, short = tmp_path / "full", tmp_path / "short"
    assert main(["render", str(stage_scene_dir), "--out", str(full), "--spp", "16", "--max-bounces", "6"]) == 0
    assert main(["render", str(stage_scene_dir), "--out", str(short), "--spp", "16", "--max-bounces", "1"]) == 0
    # Each bounce adds the light it carries: a one-bounce image is darker, by the interreflections
    # of a white-ish closed room (several percent at least).
    assert read_image(short / "view.exr").mean() < 0.97 * read_image(full / "view.exr").mean()
    bad = tmp_path / "bad"
    assert main(["render", str(stage_scene_dir), "--out", str(bad), "--set", "sparkle=true"]) == 2
    assert not bad.exists()
