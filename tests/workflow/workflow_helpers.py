"""Helpers of the workflow tests: they run `snakemake` as a subprocess on the repository's
Snakefile, in a temporary working directory, with the toy config beside this file."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
SNAKEFILE = REPO / "Snakefile"
TEST_CONFIG = Path(__file__).with_name("config.yaml")
LOCAL_PROFILE = REPO / "workflow" / "profiles" / "local"
BIN = Path(sys.executable).parent


def snakemake_env() -> dict:
    """The environment of the runs: this interpreter's bin first (its `invrender`), and the
    kernel binary cache of the session (INVRENDER_CACHE, else ~/.cache/invrender) kept."""
    env = dict(os.environ)
    env["PATH"] = f"{BIN}{os.pathsep}{env.get('PATH', '')}"
    return env


def snakemake(workdir, *args, config=TEST_CONFIG, check=True, timeout=600, env=None, **popen):
    """Run snakemake on the repository's Snakefile in ``workdir``; returns the CompletedProcess
    (stdout and stderr together in .stdout). ``config=None`` uses only the Snakefile's
    configfile (the default demo config, which must then exist in ``workdir``); ``env`` adds
    variables to the environment."""
    cmd = [sys.executable, "-m", "snakemake", "-s", str(SNAKEFILE), "--directory", str(workdir)]
    if config is not None:
        cmd += ["--configfile", *map(str, [config] if isinstance(config, (str, Path)) else config)]
    cmd += [str(a) for a in args]
    result = subprocess.run(
        cmd,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env={**snakemake_env(), **(env or {})},
        timeout=timeout,
        **popen,
    )
    if check and result.returncode != 0:
        raise AssertionError(f"snakemake {' '.join(cmd[6:])} failed ({result.returncode}):\n{result.stdout[-6000:]}")
    return result


def job_counts(output: str) -> dict[str, int]:
    """The 'Job stats' table of a snakemake run or dry run, as {rule: count} (without total);
    {} when nothing is to be done."""
    match = re.search(r"Job stats:\n.*?\n-+\s+-+\n(.*?)\ntotal\s+\d+", output, re.S)
    if not match:
        return {}
    counts = {}
    for line in match.group(1).splitlines():
        rule, count = line.split()
        counts[rule] = int(count)
    return counts


def read_image(path) -> np.ndarray:
    """(H, W, C) linear float32: EXR as stored, PNG decoded from sRGB."""
    from invrender.scene.images import read_image as read

    return read(path)


def read_json(path):
    return json.loads(Path(path).read_text())


def colmap_image_names(model_dir) -> list[str]:
    import pycolmap

    reconstruction = pycolmap.Reconstruction(str(model_dir))
    return sorted(image.name for image in reconstruction.images.values())


def ran_jobs(output: str) -> dict[str, int]:
    """The jobs a run (or dry run) announced, as {rule: count}: unlike the 'Job stats' table,
    printed before the segment checkpoint has run, this counts the per-instance jobs
    (duplicates_crop) the checkpoint added."""
    counts: dict[str, int] = {}
    for rule in re.findall(r"(?m)^(?:local)?(?:rule|checkpoint) (\w+):$", output):
        counts[rule] = counts.get(rule, 0) + 1
    return counts


# The jobs of a complete run of the test config (and of the demo) as planned before the segment
# checkpoint has run: the room (multiview) is recovered, evaluated and edited; the duplicates
# scene is segmented, solved, baked and evaluated. Once the checkpoint has run, one
# duplicates_crop job per instance it found joins them (ran_jobs counts those).
FULL_RUN_JOBS = {
    "synthesize": 2,
    "cameras": 2,
    "geometry": 2,
    "segment": 1,
    "duplicates": 1,
    "gradients": 1,
    "milo_train": 1,
    "bake": 1,
    "duplicates_material": 1,
    "bake_duplicates": 1,
    "features": 2,
    "render": 2,
    "export": 2,
    "evaluate": 1,
    "evaluate_duplicates": 1,
    "edit": 1,
    "recovery_run": 3,  # the test config's recovery sweep: 2 MILO runs, 1 of the material stage
    "accuracy": 2,
    "summary": 2,
    "all": 1,
}


def end_process(process: subprocess.Popen, sig: int, timeout: float) -> None:
    """Ask a still running process to stop with `sig`; kill it if it has not within `timeout` s."""
    if process.poll() is not None:
        return
    process.send_signal(sig)
    try:
        process.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        process.kill()
        process.communicate()
