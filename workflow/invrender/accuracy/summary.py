"""The summary (`invrender summary`, rule summary): a scene's numbers for the Snakemake report.

    out_dir/runtime.html    each rule's wall time, CPU time and peak memory, from the
                            `benchmark:` records results/{scene}/benchmarks/**/*.tsv
    out_dir/runtime.png     the same as bars
    out_dir/metrics.html    with a synthetic scene's evaluation (report/metrics.json): each
                            metric beside the best constant guess's (each map the truth's mean
                            on the surface) and the paper's value (MILO Table 3, SfD Table 2)

The report shows HTML in a frame, so tables are HTML; every table written has rows.
"""

from __future__ import annotations

import csv
import html
import json
import logging
from pathlib import Path

from ..scene.atomic import atomic_dir, check_output

log = logging.getLogger(__name__)
STYLE = (
    "<style>table{border-collapse:collapse;font:12px sans-serif}td,th{border:1px solid #ccc;padding:2px 6px}</style>"
)


def run(results_dir, out_dir) -> dict:
    results_dir, out_dir = Path(results_dir), Path(out_dir)
    check_output(out_dir, "summary")
    runtimes = benchmark_rows(results_dir / "benchmarks")
    metrics = metric_rows(results_dir / "report" / "metrics.json")
    with atomic_dir(out_dir, kind="summary") as tmp:
        tmp = Path(tmp)
        columns = ["rule", "wall seconds", "CPU seconds", "peak RSS [MB]", "mean load [%]"]
        (tmp / "runtime.html").write_text(page("Time and memory per rule", columns, runtimes))
        runtime_figure(tmp / "runtime.png", runtimes)
        if metrics:
            columns = ["metric", "ours", "a constant guess", "paper", "where in the paper"]
            (tmp / "metrics.html").write_text(page("Metrics beside the paper's", columns, metrics))
    log.info("summary: %d rules timed, %d metrics beside the paper's", len(runtimes), len(metrics))
    return {"runtimes": runtimes, "metrics": metrics}


def benchmark_rows(directory: Path) -> list[dict]:
    """One row per benchmark record (a per-instance rule's records as rule/instance)."""
    rows = []
    for path in sorted(directory.rglob("*.tsv")) if directory.is_dir() else []:
        with open(path, newline="") as handle:
            records = list(csv.DictReader(handle, delimiter="\t"))
        if not records:
            continue
        record = records[-1]  # a rule run with --benchmark-repeats: the last repeat
        rows.append(
            {
                "rule": str(path.relative_to(directory).with_suffix("")),
                "wall seconds": _number(record.get("s")),
                "CPU seconds": _number(record.get("cpu_time")),
                "peak RSS [MB]": _number(record.get("max_rss")),
                "mean load [%]": _number(record.get("mean_load")),
            }
        )
    return rows


def _number(value):
    try:
        return float(value)
    except (TypeError, ValueError):
        return None


def metric_rows(path: Path) -> list[dict]:
    """Ours beside the paper's: MILO's section 4.1 and Table 3 for a multiview scene, Structure
    from Duplicates' Table 2 for a duplicates scene."""
    if not path.is_file():
        return []
    document = json.loads(path.read_text())
    if document.get("mode") == "duplicates":
        return _duplicates_rows(document)
    paper, rows = document["paper"], []
    maps = document["maps"]
    rows.append(
        {
            "metric": "light maps MSE",
            "ours": maps["light_maps_mse"],
            "a constant guess": maps.get("constant_guess", {}).get("light_maps_mse"),
            "paper": paper["light_maps_mse"],
            "where in the paper": "MILO section 4.1",
        }
    )
    rows.append(
        {
            "metric": "material MSE",
            "ours": maps["material_mse"],
            "a constant guess": maps.get("constant_guess", {}).get("material_mse"),
            "paper": paper["material_mse"],
            "where in the paper": "MILO section 4.1",
        }
    )
    for key, name in (("psnr_db", "PSNR [dB]"), ("ssim", "SSIM"), ("ncc", "NCC"), ("mse", "MSE")):
        rows.append(
            {
                "metric": f"insertion {name}",
                "ours": document["insertion"]["mean"][key],
                "paper": paper["insertion"][key],
                "where in the paper": "MILO Table 3",
            }
        )
    if document.get("novel_views"):
        rows.append(
            {
                "metric": "novel-view PSNR [dB]",
                "ours": document["novel_views"]["mean"]["psnr_db"],
                "paper": None,
                "where in the paper": "-",
            }
        )
    return rows


def paper_copies(table: dict, copies: int) -> str:
    """The key of the paper's Table 2 row nearest to ``copies`` (6, 10 or 20 copies): a scene is
    compared with the row of its own size, not always with one."""
    return min(table, key=lambda key: (abs(int(key) - copies), int(key)))


def _duplicates_rows(document: dict) -> list[dict]:
    table = document["paper"]["table2_color_box"]
    copies = paper_copies(table, len(document["masks"]["instances"]))
    paper, where = table[copies], f"SfD Table 2 ({copies} copies)"
    after = document["poses"]["after"]
    rows = [
        {"metric": "mean mask IoU", "ours": document["masks"]["mean_iou"], "paper": None, "where in the paper": "-"}
    ]
    if after.get("rotation"):
        rows.append(
            {
                "metric": "rotation error, mean [deg]",
                "ours": after["rotation"]["error_deg"]["mean"],
                "paper": paper["rotation_deg"],
                "where in the paper": where,
            }
        )
    if after.get("translation"):
        rows.append(
            {
                "metric": "translation error [fraction of diagonal]",
                "ours": after["translation"]["error_fraction_of_diagonal"]["mean"],
                "paper": paper["translation"],
                "where in the paper": where,
            }
        )
    if document.get("mesh"):
        rows.append(
            {
                "metric": "Chamfer distance",
                "ours": document["mesh"]["chamfer_m"],
                "paper": paper["chamfer"],
                "where in the paper": where,
            }
        )
    surface = (document.get("appearance") or {}).get("object") or {}
    if "constant_guess" in surface:
        rows.append(
            {
                "metric": "albedo PSNR [dB]",
                "ours": surface["albedo"]["psnr_db"],
                "a constant guess": surface["constant_guess"]["albedo"]["psnr_db"],
                "paper": None,
                "where in the paper": "-",
            }
        )
    return rows


def html_table(columns, rows: list[dict]) -> str:
    """One HTML table: a column per name, a row per dict (missing values as '-')."""
    head = "".join(f"<th>{html.escape(c)}</th>" for c in columns)
    body = "".join(
        "<tr>" + "".join(f"<td>{html.escape(_cell(r.get(c)))}</td>" for c in columns) + "</tr>" for r in rows
    )
    return f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


def page(title: str, columns: list[str], rows: list[dict]) -> str:
    return (
        f"<!doctype html><html><head><meta charset='utf-8'><title>{html.escape(title)}</title>{STYLE}</head>"
        f"<body><h3>{html.escape(title)}</h3>{html_table(columns, rows)}</body></html>\n"
    )


def _cell(value) -> str:
    if value is None:
        return "-"
    if isinstance(value, float):
        return f"{value:.4g}"
    return str(value)


def runtime_figure(path: Path, rows: list[dict]) -> None:
    from ..scene.atomic import atomic_path
    from .figures import pyplot

    plt = pyplot()
    names = [r["rule"] for r in rows] or ["(no records)"]
    fig, axes = plt.subplots(1, 2, figsize=(10, 0.35 * len(names) + 1.5), squeeze=False)
    for ax, key in zip(axes[0], ("wall seconds", "peak RSS [MB]")):
        ax.barh(names, [r[key] or 0 for r in rows] or [0])
        ax.set_xlabel(key)
        ax.invert_yaxis()
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=100, format="png")
    plt.close(fig)
