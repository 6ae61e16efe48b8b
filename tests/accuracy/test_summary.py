"""The report's summary tables: each rule's benchmark record, the metrics beside the paper's."""

from __future__ import annotations

import json

from invrender.accuracy import summary
from invrender.scene.images import read_image

# a snakemake benchmark record, as the rules' `benchmark:` write it
RECORD = (
    "s\th:m:s\tmax_rss\tmax_vms\tmax_uss\tmax_pss\tio_in\tio_out\tmean_load\tcpu_time\n"
    "{s}\t0:00:01\t{rss}\t1\t1\t1\t0\t0\t50\t{cpu}\n"
)


def test_summary_tables_have_a_row_per_record_and_metric(tmp_path):
    results = tmp_path / "results" / "room"
    (results / "benchmarks" / "duplicates_crop").mkdir(parents=True)
    (results / "benchmarks" / "render.tsv").write_text(RECORD.format(s=38.19, rss=179.66, cpu=29.67))
    (results / "benchmarks" / "duplicates_crop" / "3.tsv").write_text(RECORD.format(s=2.5, rss=90.0, cpu=2.0))
    (results / "report").mkdir()
    metrics = {
        "paper": {
            "light_maps_mse": 0.002,
            "material_mse": 0.015,
            "insertion": {"psnr_db": 26.49, "ssim": 0.964, "ncc": 0.978, "mse": 0.002},
        },
        "maps": {
            "light_maps_mse": 0.023,
            "material_mse": 0.025,
            "constant_guess": {"light_maps_mse": 0.024, "material_mse": 0.018},
        },
        "insertion": {"mean": {"psnr_db": 22.0, "ssim": 0.33, "ncc": 0.83, "mse": 0.006}},
        "novel_views": {"mean": {"psnr_db": 23.5}},
    }
    (results / "report" / "metrics.json").write_text(json.dumps(metrics))
    document = summary.run(results, tmp_path / "summary")
    assert [r["rule"] for r in document["runtimes"]] == ["duplicates_crop/3", "render"]
    assert document["runtimes"][1]["wall seconds"] == 38.19 and document["runtimes"][1]["peak RSS [MB]"] == 179.66
    rows = {r["metric"]: r for r in document["metrics"]}
    assert rows["material MSE"]["ours"] == 0.025 and rows["material MSE"]["paper"] == 0.015
    assert rows["material MSE"]["a constant guess"] == 0.018 and rows["light maps MSE"]["a constant guess"] == 0.024
    assert rows["insertion PSNR [dB]"]["paper"] == 26.49
    text = (tmp_path / "summary" / "metrics.html").read_text()
    assert text.count("<tr><td>") == 7 and "26.49" in text and "a constant guess" in text and "0.018" in text
    assert (tmp_path / "summary" / "runtime.html").read_text().count("<tr><td>") == 2
    assert read_image(tmp_path / "summary" / "runtime.png").shape[1] > 300


def test_duplicates_metrics_sit_beside_the_paper_row_of_their_own_copy_count(tmp_path):
    # the paper's Table 2, written out here (not imported): rotation in degrees per copy count
    table = {"6": {"rotation_deg": 2.515}, "10": {"rotation_deg": 0.186}, "20": {"rotation_deg": 0.299}}
    rows_for = {}
    for copies in (5, 6, 9, 12, 20, 30):
        metrics = {
            "mode": "duplicates",
            "paper": {"table2_color_box": {k: {**v, "translation": 0.0, "chamfer": 0.0} for k, v in table.items()}},
            "masks": {"mean_iou": 0.9, "instances": [{"iou": 0.9}] * copies},
            "poses": {"after": {"rotation": {"error_deg": {"mean": 1.0}}}},
        }
        path = tmp_path / f"{copies}.json"
        path.write_text(json.dumps(metrics))
        row = {r["metric"]: r for r in summary.metric_rows(path)}["rotation error, mean [deg]"]
        rows_for[copies] = (row["paper"], row["where in the paper"])
    assert rows_for[5] == rows_for[6] == (2.515, "SfD Table 2 (6 copies)")
    assert rows_for[9] == rows_for[12] == (0.186, "SfD Table 2 (10 copies)")
    assert rows_for[20] == rows_for[30] == (0.299, "SfD Table 2 (20 copies)")
