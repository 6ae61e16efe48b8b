"""The `invrender bench export` harness at its --quick sizes (the room at 32 x 24, 2 views): it runs
end to end through the CLI, writes its tables, and its numbers are well formed. The full run and
its reading are in docs/export.md ("What a round trip keeps, measured")."""

import json

import numpy as np

import invrender.mitsuba as mb  # noqa: I001 - first: it points drjit at a usable libLLVM
from invrender.bench.export import TABLES, psnr
from invrender.cli import main


def test_quick_run_writes_every_table(tmp_path):
    assert main(["bench", "export", "--quick", "--out", str(tmp_path)]) == 0
    report = json.loads((tmp_path / "export.json").read_text())
    assert report["mitsuba_variant"] == mb.DEFAULT_VARIANT
    for key in TABLES:
        assert (tmp_path / f"export_{key}.csv").exists(), key
    assert (tmp_path / "export_table.md").read_text().startswith("# invrender bench export (quick")
    room, cans, exact = report["round_trip"]
    # lossless: the room and --no-instancing come back bit for bit; instancing moves the cans by
    # at most a float32 step (docs/export.md)
    assert room["psnr_per_view"] == [None, None] and room["max_abs_diff"] == 0
    assert exact["max_abs_diff"] == 0 and 0 < cans["positions_max_diff_m"] < 1e-6
    assert [row["what"] for row in report["standard_view"]][-1] == "all of the standard view"
    assert all(v is not None and np.isfinite(v) for row in report["standard_view"] for v in row["psnr_per_view"])
    noise, ggx, brightness = report["ggx"]
    assert len(ggx["psnr_per_view"]) == 1 and brightness["psnr_db"].endswith("%")


def test_psnr_peak_is_the_reference_99th_percentile():
    reference = np.linspace(0.0, 1.0, 10_001).reshape(-1, 1)
    assert np.isclose(psnr(reference, reference + 0.01), 20 * np.log10(0.99 / 0.01))
    assert psnr(reference, reference) == float("inf")
