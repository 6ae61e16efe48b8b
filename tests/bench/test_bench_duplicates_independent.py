"""bench/duplicates_independent.py: the duplicates captures Mitsuba 3 renders, drawn per name, and
their photograph as a camera writes it (8-bit sRGB)."""

import json

import numpy as np
import pytest

from invrender.bench import duplicates as bench
from invrender.bench import duplicates_independent as independent
from invrender.scene.images import read_image, srgb_to_linear
from invrender.scene.types import SceneError
from invrender.synthesize.duplicates import make_duplicates


def test_each_capture_is_drawn_from_its_name_and_the_splits_differ():
    configs = {name: independent.independent_config(name) for name in independent.INDEPENDENT_SCENES}
    assert configs["mbox-10-tuning"] == independent.independent_config("mbox-10-tuning")  # the name alone
    for count in independent.COUNTS:
        (tuning, _), (held_out, _) = configs[f"mbox-{count}-tuning"], configs[f"mbox-{count}-held-out"]
        assert tuning["seed"] != held_out["seed"] and tuning["object"]["size"] != held_out["object"]["size"]
        assert tuning["camera"] != held_out["camera"] and tuning["count"] == held_out["count"] == count
    for config, spp in configs.values():
        assert len(set(config["object"]["size"])) == 3 and spp in independent.SPP_CHOICES
        _, metadata = make_duplicates(config)  # every copy placed apart and in view
        assert len(metadata["poses"]["instances"]) == config["count"]


def test_the_bench_names_them_and_runs_both_mask_sources():
    settings = bench.settings_from(False, "independent", None, None)
    assert settings.scenes == list(independent.INDEPENDENT_SCENES)
    assert all(settings.variants[s] == list(bench.INDEPENDENT_VARIANTS) for s in settings.scenes)
    assert {bench.mask_source(v) for v in bench.INDEPENDENT_VARIANTS} == {"provided", "opencv"}
    with pytest.raises(SceneError, match="mbox-6-tuning"):
        bench.settings_from(False, "mbox-7-tuning", None, None)


def test_the_photograph_is_the_8_bit_srgb_image_mitsuba_rendered(tmp_path, monkeypatch):
    monkeypatch.setattr(independent, "WIDTH", 96)
    monkeypatch.setattr(independent, "HEIGHT", 72)
    monkeypatch.setattr(independent, "SPP_CHOICES", (4,))
    out = tmp_path / "mbox-6-tuning"
    independent.render("mbox-6-tuning", out)
    photo = read_image(out / "images" / "view_000.exr")
    levels = srgb_to_linear(np.arange(256) / 255.0).astype(np.float32)
    assert photo.shape == (72, 96, 3)
    assert np.isin(photo, levels).all()  # on the 256 levels of an 8-bit sRGB file, nothing between
    assert len(np.unique(photo)) > 50  # and an image, not a constant
    assert json.loads((out / "independent.json").read_text())["spp"] == 4
    assert not (tmp_path / "mbox-6-tuning.partial").exists()
