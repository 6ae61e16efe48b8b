"""`python -m invrender.materials`: the contact sheet's layout and swatch colours, and `match`
on a crop file (in-process: the command's own parsing and output)."""

import json

import numpy as np
import torch

from invrender.materials import PRESETS
from invrender.materials.__main__ import main
from invrender.scene.images import linear_to_srgb, read_image, write_exr


def test_thumbnails_contact_sheet(tmp_path, capsys):
    out = tmp_path / "sheet.png"
    assert main(["thumbnails", str(out), "--size", "32", "--columns", "4"]) == 0
    info = json.loads(capsys.readouterr().out)
    sheet = read_image(out)  # back to linear
    # 10 presets in 4 columns: 3 rows of 32 + 14 (label) + 4 (margin), plus the outer margin
    assert sheet.shape == (3 * 50 + 4, 4 * 36 + 4, 3) == (info["height"], info["width"], 3)
    # the first swatch is plain grey 0.5: its 8-bit sRGB code decodes back to within a step
    swatch = sheet[4:36, 4:36]
    assert np.allclose(swatch, 0.5, atol=0.004)
    # the second is the checker: both its colours show
    checker = sheet[4:36, 40:72].mean(axis=2)
    assert checker.max() > 0.75 and checker.min() < 0.15
    assert np.round(linear_to_srgb(np.float32(0.5)) * 255) == 188


def test_match_prints_a_ranking_and_a_fit(tmp_path, capsys):
    preset = next(p for p in PRESETS if p.name == "tiles_brick")
    with torch.no_grad():
        crop = preset.type.image(48, preset.params(), preset.thumbnail).numpy()
    path = tmp_path / "crop.exr"
    write_exr(path, crop)
    # three presets keep the library's descriptors to 108 renders (test_retrieval_fit has all)
    assert (
        main(["match", str(path), "--steps", "3", "--top", "3", "--presets", "plain_grey,tiles_brick,checker_bw"]) == 0
    )
    result = json.loads(capsys.readouterr().out)
    assert result["material"] == "tiles" and result["ranking"][0]["preset"] == "tiles_brick"
    assert len(result["ranking"]) == 3 and len(result["params"]["tile_colour"]) == 3
    assert result["loss"]["final"] <= result["loss"]["initial"] * 1.5


def test_match_names_a_bad_weights_file(tmp_path, capsys):
    crop = tmp_path / "crop.exr"
    write_exr(crop, np.full((16, 16, 3), 0.5, np.float32))
    weights = tmp_path / "w.pt"
    torch.save({"other": torch.zeros(2)}, weights)
    assert main(["match", str(crop), "--weights", str(weights)]) == 2
    assert str(weights) in capsys.readouterr().err
    assert main(["match", str(crop), "--presets", "marble"]) == 2
    assert "marble" in capsys.readouterr().err
