"""Running a stage on one input and checking the reliability property (issue 10):

either it succeeds (exit 0) with finite outputs, or it exits 2 having logged exactly one ERROR line
that names the file and the field ("<file>: <field>: expected ..."); never a traceback, a signal,
a hang past a bound, a NaN written, or a file outside the stage's output touched.

Stages whose native libraries may crash (pymeshlab, xatlas and pycolmap: geometry and cameras) run
in a subprocess with a timeout; the others run in-process through ``invrender.cli.main``.
"""

from __future__ import annotations

import contextlib
import json
import os
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

import invrender
from invrender.cli import main

WORKFLOW = Path(invrender.__file__).resolve().parents[1]
TIMEOUT_S = 120  # a bound on any run of these small inputs: more is a hang


@dataclass
class Outcome:
    code: int  # exit status; negative: killed by that signal
    errors: list[str]  # the ERROR lines of the log, without their timestamp
    stderr: str


def snapshot(root: Path, out: Path) -> dict:
    """Every file under root except the stage's output: path -> (size, mtime_ns)."""
    found = {}
    for path in root.rglob("*"):
        if path == out or out in path.parents or not path.is_file():
            continue
        stat = path.stat()
        found[path] = (stat.st_size, stat.st_mtime_ns)
    return found


def run_stage(argv: list[str], log: Path, subprocess_run: bool) -> Outcome:
    """``invrender --log LOG *argv``, in-process or in a subprocess bounded by TIMEOUT_S, run from
    the log's directory (so that a stray relative write lands where the snapshot sees it)."""
    argv = ["--log", str(log), *map(str, argv)]
    if subprocess_run:
        env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(WORKFLOW), os.environ.get("PYTHONPATH", "")]))
        try:
            done = subprocess.run(
                [sys.executable, "-m", "invrender.cli", *argv],
                capture_output=True,
                text=True,
                timeout=TIMEOUT_S,
                env=env,
                cwd=log.parent,
            )
        except subprocess.TimeoutExpired:
            raise AssertionError(f"invrender {' '.join(argv)} ran past {TIMEOUT_S} s (a hang)") from None
        code, stderr = done.returncode, done.stderr
    else:
        with contextlib.chdir(log.parent):
            code, stderr = main(argv), ""
    lines = log.read_text().splitlines() if log.exists() else []
    errors = [line.split(" ERROR ", 1)[1] for line in lines if " ERROR " in line]
    return Outcome(code, errors, stderr)


def assert_finite_outputs(out: Path) -> None:
    """Every JSON strict (no NaN), every EXR and npz array finite (a depth AOV may be +inf on a
    miss, never NaN)."""
    from invrender.scene.images import read_image

    for path in out.rglob("*"):
        if path.suffix == ".json":
            json.loads(path.read_text(), parse_constant=lambda token: _fail(f"{path}: {token} written"))
        elif path.suffix == ".exr":
            image = read_image(path, finite=False)
            bad = np.isnan(image) if path.stem.endswith("_depth") else ~np.isfinite(image)
            assert not bad.any(), f"{path}: {int(bad.sum())} non-finite values written"
        elif path.suffix == ".npz":
            with np.load(path) as arrays:
                for name in arrays.files:
                    a = arrays[name]
                    assert not (np.issubdtype(a.dtype, np.floating) and not np.isfinite(a).all()), f"{path}:{name}"


def _fail(message):
    raise AssertionError(message)


def check_property(
    root: Path, out: Path, argv: list[str], subprocess_run: bool, names: tuple[str, ...] = ()
) -> Outcome:
    """Run one stage on inputs under ``root`` writing ``out``, and assert the property. ``names``:
    words of which the error line must contain one (the input file or directory names)."""
    log = root / "run.log"
    if log.exists():
        log.unlink()
    before = snapshot(root, out)
    outcome = run_stage(argv, log, subprocess_run)
    after = snapshot(root, out)
    after.pop(log, None)
    before.pop(log, None)
    assert after == before, f"files outside {out} changed: {sorted(set(after.items()) ^ set(before.items()))[:4]}"
    assert "Traceback" not in outcome.stderr, outcome.stderr[-3000:]
    assert outcome.code in (0, 2), f"exit {outcome.code} (negative: a signal)\n{outcome.stderr[-3000:]}"
    if outcome.code == 0:
        assert not outcome.errors, outcome.errors
        assert out.exists(), f"exit 0 without {out}"
        assert_finite_outputs(out)
    else:
        assert len(outcome.errors) == 1, outcome.errors
        line = outcome.errors[0]
        assert ": expected " in line and "\n" not in line, line
        assert not names or any(name in line for name in names), (names, line)
        # temporary outputs are named after the output, hidden (a leading dot) or not
        leftovers = [p.name for p in out.parent.iterdir() if p.name.lstrip(".").startswith(out.name)]
        assert not leftovers, f"a failed run left {leftovers}"
    return outcome
