"""`invrender bench accuracy`: the accuracy stage's `full` sweep (`--quick`: its `quick` one)
on the demo's room and boxes (the scenes the accuracy rule takes), through the workflow itself.

Runs `snakemake` on the demo config (config/config.yaml) in ``WORK`` (default
results/bench/accuracy), with `accuracy.budget` set, for each scene's `accuracy` target: the
demo chain (synthesize, cameras, geometry, MILO-Net or the duplicates stages, bake, evaluate),
the recovery sweep's runs (rule recovery_run, one job each, config accuracy.recovery.<budget>),
then the accuracy rule (the forward and gradient sweeps on the recovered scene, the recovery
rows from the configured run and the sweep's, the knees, the recovery knee trained again on
another seed). Everything is cached in ``WORK``: a second call redoes only what changed. Copies
the room's accuracy/ to ``OUT/accuracy/`` and the boxes' to ``OUT/accuracy_boxes/``, with each
rule's time from its benchmark record in ``OUT/accuracy*/jobs.csv``.

``demo_room`` writes the demo room's truth scene, features and captured images; the accuracy
tests share it.
"""

from __future__ import annotations

import csv
import json
import logging
import shutil
import subprocess
import sys
from pathlib import Path

log = logging.getLogger("invrender.bench")

DEFAULT_WORK = "results/bench/accuracy"
CAPTURE_SPP = 16  # the captured images: the gradient sweep's loss


def demo_room(root, cameras: int = 2, capture_spp: int = CAPTURE_SPP, device=None):
    """Write the demo room under ``root``: scene/, features.json, images/ (one per camera).
    Returns (scene, features)."""
    from ..render.analysis import analyse
    from ..render.renderer import Renderer
    from ..scene.format import write_scene
    from ..scene.images import write_exr
    from ..synthesize.room import make_room

    root = Path(root)
    scene, _ = make_room({"cameras": {"count": cameras}})
    write_scene(root / "scene", scene)
    features = analyse(scene, device=device)
    (root / "features.json").write_text(json.dumps(features.to_json()))
    (root / "images").mkdir(exist_ok=True)
    renderer = Renderer(scene, features, device)
    for camera in scene.cameras:
        image = renderer.render(camera, capture_spp, 7, aovs=False)["radiance"]
        write_exr(root / "images" / camera.name, image)
    return scene, features


REPO = Path(__file__).resolve().parents[3]
SCENES = {"room": "accuracy", "boxes": "accuracy_boxes"}  # scene -> folder under OUT


def snakemake_command(work, budget: str, device: str | None) -> list[str]:
    command = [
        sys.executable, "-m", "snakemake", "-s", str(REPO / "Snakefile"), "--directory", str(work),
        "--configfile", str(REPO / "config" / "config.yaml"), str(REPO / "config" / "accuracy-sweep.yaml"),
        "--workflow-profile", str(REPO / "workflow" / "profiles" / "local"),
        *(f"results/{scene}/accuracy" for scene in SCENES),
        "--config", f"accuracy={{budget: {budget}}}",
    ]  # fmt: skip
    if device:  # --config takes every value after it: last
        command.append(f"device={device}")
    return command


def job_times(results: Path) -> list[dict]:
    """Each rule's wall and CPU seconds from its benchmark record (results/{scene}/benchmarks)."""
    rows = []
    for path in sorted((results / "benchmarks").rglob("*.tsv")):
        with open(path, newline="") as handle:
            record = next(csv.DictReader(handle, delimiter="\t"))
        rule = str(path.relative_to(results / "benchmarks").with_suffix(""))
        rows.append({"job": rule, "wall_s": float(record["s"]), "cpu_s": float(record["cpu_time"])})
    return rows


def run(quick: bool = False, out="docs/benchmarks", device: str | None = None, work=DEFAULT_WORK) -> dict:
    from ..render.measure import write_csv
    from ..scene.atomic import MARKER, atomic_dir

    budget = "quick" if quick else "full"
    work = Path(work).absolute()
    work.mkdir(parents=True, exist_ok=True)
    log.info("bench accuracy: the %s budget through the workflow in %s", budget, work)
    done = subprocess.run(
        snakemake_command(work, budget, device), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
    )
    (work / "bench_accuracy.log").write_text(done.stdout)
    if done.returncode != 0:
        tail = "\n".join(done.stdout.splitlines()[-30:])
        raise RuntimeError(f"bench accuracy: snakemake failed ({done.returncode}); {work}/bench_accuracy.log:\n{tail}")
    documents = {}
    for scene, folder in SCENES.items():
        results = work / "results" / scene
        with atomic_dir(Path(out) / folder, kind="accuracy") as tmp:
            for path in (results / "accuracy").iterdir():
                if path.is_file() and path.name != MARKER:
                    shutil.copy2(path, Path(tmp) / path.name)
            write_csv(Path(tmp) / "jobs.csv", job_times(results))
        documents[scene] = json.loads((results / "accuracy" / "accuracy.json").read_text())
    return documents
