"""`invrender bench traversal` at its --quick sizes: through the CLI, and as an A/B against a
copy of this source tree, which must find the same hit for every ray. Nothing here is a
measurement: the full run and its reading are in docs/benchmarks.md ("Traversal")."""

import json
import math
import shutil

from invrender.bench.traversal import QUICK, TREE, run
from invrender.cli import main


def test_quick_run_writes_its_table(tmp_path):
    assert main(["bench", "traversal", "--quick", "--out", str(tmp_path)]) == 0
    rows = json.loads((tmp_path / "traversal.json").read_text())["traversal"]
    assert [row["triangles"] for row in rows][0] == 2644 and len(rows) == len(QUICK.sizes)
    for row in rows:
        for key in ("camera_rays_per_s", "bounce_rays_per_s", "render_b1_rays_per_s"):
            assert math.isfinite(row[key]) and row[key] > 0, key
        assert 1 <= row["camera_nodes_per_ray"] and 0 < row["camera_tris_per_ray"] <= 8 * row["camera_nodes_per_ray"]
    assert (tmp_path / "traversal_table.md").read_text().startswith("# invrender bench traversal (quick")


def test_a_tree_against_its_copy_finds_the_same_hits(tmp_path):
    for name in ("kernels", "workflow"):
        shutil.copytree(TREE / name, tmp_path / "copy" / name, ignore=shutil.ignore_patterns("__pycache__"))
    rows = run(quick=True, out=tmp_path / "out", baseline=tmp_path / "copy")["traversal"]
    assert [row["tree"] for row in rows] == ["this", "baseline"] * len(QUICK.sizes)
    for this in rows[::2]:
        assert this["camera_rays_differ"] == 0 and this["bounce_rays_differ"] == 0 and this["max_rel_dt"] == 0
        assert this["x_camera_s"] > 0  # a ratio is reported (its value is load, not a test: see the bench)
