"""`invrender bench summary`: the README's table of headline results, made from the JSON files the
benchmarks wrote under docs/benchmarks/ and written between two marker lines of README.md.

    invrender bench summary [--out docs/benchmarks] [--readme README.md]

It reads (relative to ``--out``, where the benchmarks write):

    duplicates_tracks/duplicates.json             bench duplicates, variant provided-asift-tracks:
                                                  poses and shared mesh from the photograph alone
    duplicates_tracks/duplicates_material.json    bench duplicates-material on those poses
    room.json                                     bench room, its `stages` rows
    accuracy/accuracy.json                        bench accuracy: the demo room's knees
    milo-independent.json                         bench milo: rooms rendered by Mitsuba, each
                                                  recovery beside the constant guess
    duplicates-independent.json                   bench duplicates --scenes independent: boxes
                                                  rendered by Mitsuba, the capture's masks

Nothing is measured or computed here: every cell is a number of those files (the paper's too,
which the benchmarks store beside ours), formatted. Under the table it writes the command and the
date it ran. tests/bench/test_bench_summary.py fails when the README's table is not what the
committed files give, so a table edited by hand, or a benchmark re-run without this, is caught.
"""

from __future__ import annotations

import datetime
import json
import os
import re
from pathlib import Path

from ..scene.types import SceneError

BEGIN = "<!-- bench summary: begin (written by `invrender bench summary` from docs/benchmarks/*.json) -->"
END = "<!-- bench summary: end -->"
COMMAND = "invrender bench summary"
SOURCES = {
    "poses": "duplicates_tracks/duplicates.json",
    "material": "duplicates_tracks/duplicates_material.json",
    "room": "room.json",
    "accuracy": "accuracy/accuracy.json",
    "milo": "milo-independent.json",
    "independent_poses": "duplicates-independent.json",
}
HEADER = ("result", "scenes", "invrender", "paper")
DATE = re.compile(r"on (\d{4}-\d{2}-\d{2}) from")

# (what, source, our key, paper key, format): one row per line, the scenes in the benchmark's order
SFD_ROWS = (
    ("Structure from Duplicates: rotation error, mean [deg]", "poses", "rot_after_mean", "paper_rot", ".3f"),
    ("translation error [object diagonal]", "poses", "trans_after_mean", "paper_trans", ".4f"),
    ("shared mesh, Chamfer distance [object diagonal]", "poses", "chamfer", "paper_chamfer", ".4f"),
    ("albedo PSNR [dB]", "material", "albedo_psnr_db", "albedo_psnr_db_paper_copies", ".2f"),
    ("relighting PSNR, copies rearranged [dB]", "material", "relighting_psnr_db", "relighting_psnr_db_paper", ".2f"),
    ("environment MSE", "material", "env_mse", "env_mse_paper_copies", ".3f"),
)
ROOM_ROWS = (
    ("PSDR-Room: room corners in view, error [m]", "visible_corner_refined", ".3f"),
    ("mask IoU over the six classes", "iou_mean", ".3f"),
    ("photo PSNR at the photo's camera [dB]", "psnr_db", ".2f"),
    ("albedo PSNR on the surface [dB]", "albedo_psnr_db", ".2f"),
    ("light power into the room / the truth's", "power_ratio", ".2f"),
)


def load(bench_dir) -> dict[str, dict]:
    """The JSON files, by their key in SOURCES; a missing or unreadable one is refused."""
    docs = {}
    for key, name in SOURCES.items():
        path = Path(bench_dir) / name
        try:
            docs[key] = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError) as error:
            raise SceneError(path, "(file)", f"a benchmark's JSON report ({error})") from None
    return docs


def _by_scene(doc: dict, source: str, **match) -> list[dict]:
    """The table rows of ``doc`` that match, one per scene of its settings, in that order."""
    rows = []
    for scene in doc["settings"]["scenes"]:
        found = [r for r in doc["table"] if r["scene"] == scene and all(r.get(k) == v for k, v in match.items())]
        if len(found) != 1 or found[0].get("error"):
            raise SceneError(SOURCES[source], f"table, scene {scene}", f"one finished row matching {match or 'it'}")
        rows.append(found[0])
    return rows


def _join(values, fmt: str) -> str:
    return " / ".join("-" if v is None else format(v, fmt) for v in values)


# (what, the arm of bench milo's independent tables, the paper's figure)
MILO_ROWS = (
    ("MILO: material MSE, rooms rendered by Mitsuba, `texels` preset", "texels", "Table 3: 0.015 (its rooms)"),
    ("the same, MILO-Net (`cpu` preset)", "MILO-Net", "-"),
    ("the same, a constant guess (the truth's mean)", "constant guess", "-"),
)


def milo_rows(doc: dict) -> list[tuple[str, str, str, str]]:
    captures = doc["captures"]
    scenes = " / ".join(f"{c['layout']} ({c['split']})" for c in captures)
    material = [next(r for r in c["rows"] if r["metric"] == "material MSE") for c in captures]
    return [(what, scenes, _join([m.get(arm) for m in material], ".4f"), paper) for what, arm, paper in MILO_ROWS]


def rows(docs: dict[str, dict]) -> list[tuple[str, str, str, str]]:
    """(result, scenes, invrender, paper) for every line of the table."""
    out = milo_rows(docs["milo"])
    sfd = {"poses": _by_scene(docs["poses"], "poses"), "material": _by_scene(docs["material"], "material")}
    copies = " / ".join(str(r["copies"]) for r in sfd["material"]) + " boxes"
    for what, source, ours, paper, fmt in SFD_ROWS:
        theirs = [r[paper] for r in sfd[source]]
        # relighting has no per-count figure in SfD's Table 2: its Table 1 (one view) is the one
        note = "Table 1, one view: " if paper == "relighting_psnr_db_paper" else "Table 2: "
        if len(set(theirs)) == 1:
            theirs = theirs[:1]
        out.append((what, copies, _join([r[ours] for r in sfd[source]], fmt), note + _join(theirs, fmt)))
    independent = _by_scene(docs["independent_poses"], "independent_poses", variant="provided-asift-tracks")
    out.append(
        (
            "Structure from Duplicates on boxes Mitsuba rendered (their masks): rotation mean (median) [deg]",
            " / ".join(r["scene"].removeprefix("mbox-").replace("-", " ", 1) for r in independent),
            " / ".join(f"{r['rot_after_mean']:.2f} ({r['rot_after_median']:.2f})" for r in independent),
            "Table 2: " + _join([r["paper_rot"] for r in independent], ".3f"),
        )
    )
    room = _by_scene(docs["room"], "room", row="stages")
    layouts = " / ".join(r["scene"] for r in room)
    for what, key, fmt in ROOM_ROWS:
        out.append((what, layouts, _join([r[key] for r in room], fmt), "not reported"))
    accuracy = docs["accuracy"]
    scene = f"demo room, {accuracy['camera']['width']} x {accuracy['camera']['height']}"
    forward, recovery = accuracy["knees"]["forward"], accuracy["knees"]["recovery"]
    out.append(
        (
            "Accuracy against time: the renders' knee",
            scene,
            f"{forward['row']['spp']} spp: RMSE {forward['error']:.3f} in {forward['row']['time_s']:.1f} s",
            "-",
        )
    )
    row = recovery["row"]
    out.append(
        (
            "the training's knee (MILO-Net)",
            scene,
            f"`{row['label']}`, iteration {row['iteration']}: {row['error_name']} {recovery['error']:.3f} "
            f"in {row['time_s']:.0f} s",
            "-",
        )
    )
    return out


def table(header, cells, date: str, folder, sources: str, base=".") -> str:
    """A markdown table, then the command, ``date`` (YYYY-MM-DD) and its sources: ``folder``
    relative to ``base`` (the page's directory), then ``sources`` within it."""
    where = Path(os.path.relpath(Path(folder).resolve(), Path(base).resolve())).as_posix()
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(row) + " |" for row in cells]
    lines += ["", f"Generated by `{COMMAND}` on {date} from {where}/{sources}."]
    return "\n".join(lines) + "\n"


def block(bench_dir, date: str, base=".") -> str:
    """The lines between the README's markers: the table, then the command and ``date``."""
    sources = ", ".join(f"`{name}`" for name in SOURCES.values())
    return table(HEADER, rows(load(bench_dir)), date, bench_dir, f": {sources}", base)


def split(text: str, path="README.md", begin=BEGIN, end=END) -> tuple[str, str, str]:
    """(before, between, after) the marker lines of ``text``, the markers in before and after."""
    lines = text.splitlines(keepends=True)
    starts = [i for i, line in enumerate(lines) if line.rstrip("\n") == begin]
    ends = [i for i, line in enumerate(lines) if line.rstrip("\n") == end]
    if len(starts) != 1 or len(ends) != 1 or starts[0] > ends[0]:
        raise SceneError(path, "bench summary markers", f"one line {begin!r}, then one line {end!r}")
    start, end = starts[0], ends[0]
    return "".join(lines[: start + 1]), "".join(lines[start + 1 : end]), "".join(lines[end:])


def date_of(between: str) -> str | None:
    """The date an earlier run wrote under the table, or None."""
    found = DATE.search(between)
    return found.group(1) if found else None


def rewrite(readme, bench_dir, date: str | None = None, make=None, begin=BEGIN, end=END) -> str:
    """Write the table (``make``: block by default) into ``readme`` between its markers (nothing
    else changes); returns it."""
    readme = Path(readme)
    before, _, after = split(readme.read_text(encoding="utf-8"), readme, begin, end)
    text = (make or block)(bench_dir, date or datetime.date.today().isoformat(), readme.parent)
    readme.write_text(before + text + after, encoding="utf-8")
    return text


# The CPU OpenCL runtimes, each through `invrender bench render --sections equal_rmse --device D
# --out docs/benchmarks/runtimes/NAME`: the table in docs/benchmarks.md that CPU_RUNTIMES follows.
RUNTIMES = "runtimes"
RUNTIMES_PAGE = "docs/benchmarks.md"
RUNTIMES_BEGIN = "<!-- bench summary: runtimes begin (written by `invrender bench summary`) -->"
RUNTIMES_END = "<!-- bench summary: runtimes end -->"
RUNTIMES_HEADER = (
    "runtime (platform / device)",
    "B",
    "samples/s",
    "Mitsuba's samples/s",
    "time to equal RMSE: Mitsuba's / ours",
    "the same, Mitsuba given our light split",
    "load average",
)


def runtime_rows(bench_dir) -> list[tuple[str, ...]]:
    """One row per runtime and bounce count, the fastest runtime first: by its time to equal RMSE
    against Mitsuba's in the same run at the first bounce count (the runs' loads differ)."""
    runs = []
    for path in sorted((Path(bench_dir) / RUNTIMES).glob("*/render.json")):
        doc = json.loads(path.read_text(encoding="utf-8"))
        rows = [r for r in doc["equal_rmse"] if "samples_per_s_invrender" in r]
        if not rows:
            raise SceneError(path, "equal_rmse", "the rows of `bench render --sections equal_rmse`")
        runs.append((doc["machine"], rows))
    runs.sort(key=lambda run: -run[1][0]["ratio"])
    out = []
    for machine, rows in runs:
        load = " - ".join(f"{machine[key][0]:.1f}" for key in ("load_average_start", "load_average_end"))
        for row in rows:
            out.append(
                (
                    f"{machine['opencl_device']} (CPU: {machine['cpu']})",
                    str(row["bounces"]),
                    f"{row['samples_per_s_invrender'] / 1e3:,.0f} k",
                    f"{row['samples_per_s_mitsuba'] / 1e3:,.0f} k",
                    f"{row['ratio']:.2f}",
                    f"{row['ratio_mitsuba_split']:.2f}",
                    load,
                )
            )
    return out


def runtime_block(bench_dir, date: str, base=".") -> str:
    folder = Path(bench_dir) / RUNTIMES
    return table(RUNTIMES_HEADER, runtime_rows(bench_dir), date, folder, "*/render.json", base)


# The demo's own evaluations (results/{scene}/report/metrics.json of `snakemake --cores 2`, copied
# to docs/benchmarks/demo/{scene}.json): the table in docs/benchmarks.md, ours beside the constant
# guess, so that what the demo shows is read against the trivial baseline.
DEMO = "demo"
DEMO_BEGIN = "<!-- bench summary: demo begin (written by `invrender bench summary`) -->"
DEMO_END = "<!-- bench summary: demo end -->"
DEMO_HEADER = ("scene", "metric", "recovered", "a constant guess", "better is")


def _demo_metrics(doc: dict) -> list[tuple[str, float, float | None, str]]:
    """(metric, recovered, constant guess or None, "lower"/"higher") of one metrics.json."""
    if doc.get("mode") == "duplicates":
        surface = doc["appearance"]["object"]
        rotation = doc["poses"]["after"]["rotation"]["error_deg"]["mean"]
        albedo = (surface["albedo"]["psnr_db"], surface["constant_guess"]["albedo"]["psnr_db"])
        return [("rotation error, mean [deg]", rotation, None, "lower"), ("albedo PSNR [dB]", *albedo, "higher")]
    if doc.get("mode") == "room":
        material = doc["material"]
        albedo = (material["albedo"]["psnr_db"], material["constant_guess"]["albedo"]["psnr_db"])
        return [("photo PSNR [dB]", doc["photo"]["psnr_db"], None, "higher"), ("albedo PSNR [dB]", *albedo, "higher")]
    maps, guess = doc["maps"], doc["maps"]["constant_guess"]
    return [
        ("material MSE", maps["material_mse"], guess["material_mse"], "lower"),
        ("light maps MSE", maps["light_maps_mse"], guess["light_maps_mse"], "lower"),
        ("novel-view PSNR [dB]", doc["novel_views"]["mean"]["psnr_db"], None, "higher"),
    ]


def demo_block(bench_dir, date: str, base=".") -> str:
    folder = Path(bench_dir) / DEMO
    cells = [
        (f"`{path.stem}`", metric, f"{ours:.4g}", "-" if guess is None else f"{guess:.4g}", better)
        for path in sorted(folder.glob("*.json"))
        for metric, ours, guess, better in _demo_metrics(json.loads(path.read_text(encoding="utf-8")))
    ]
    return table(DEMO_HEADER, cells, date, folder, "*.json", base)


def run(quick: bool, out, device=None, readme=None) -> dict:
    """The bench entry point (``quick`` and ``device`` are not used: nothing runs): the README's
    table, and the runtimes' table of docs/benchmarks.md beside it."""
    readme = Path(readme or "README.md")
    text = rewrite(readme, out)
    page = readme.parent / RUNTIMES_PAGE
    runtimes = rewrite(page, out, make=runtime_block, begin=RUNTIMES_BEGIN, end=RUNTIMES_END)
    demo = rewrite(page, out, make=demo_block, begin=DEMO_BEGIN, end=DEMO_END)
    print(text, runtimes, demo, sep="", end="")
    return {"readme": str(readme), "table": text, "runtimes": runtimes, "demo": demo}
