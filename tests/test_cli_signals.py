"""A stage stopped by SIGINT or SIGTERM (Ctrl-C, scancel, a time limit, Snakemake stopping its
jobs) exits 130 or 143 and leaves nothing half-written behind; after SIGKILL, which no process can
answer, the next run of the stage sweeps what the killed one left (issue 10, defect 3)."""

import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from stage_runs import STAGES, args, build_inputs

from invrender.cli import main

# Runs one stage with its atomic output held open: after the stage has written everything into
# its temporary output (all native modules imported, OpenCL set up) it says so and waits, so a
# signal lands while a complete-looking temporary directory exists beside the output.
PAUSED = """
import sys, time
from contextlib import contextmanager
from pathlib import Path
import invrender.scene.atomic as atomic

flag, out = Path(sys.argv[1]), Path(sys.argv[2])
real = {"atomic_dir": atomic.atomic_dir, "atomic_path": atomic.atomic_path}

def paused(name):
    @contextmanager
    def wrapper(path, *args, **kwargs):
        with real[name](path, *args, **kwargs) as tmp:
            yield tmp
            if Path(path) == out:
                flag.write_text("busy")
                time.sleep(300)
    return wrapper

for name in real:
    for module in [atomic] + [m for k, m in list(sys.modules.items()) if k.startswith("invrender.")]:
        if getattr(module, name, None) is real[name]:
            setattr(module, name, paused(name))
from invrender.cli import main
sys.exit(main(sys.argv[3:]))
"""


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    return build_inputs(tmp_path_factory.mktemp("inputs"))


def out_path(folder: Path, stage: str) -> Path:
    return folder / ("features.json" if stage == "features" else "out")


def start_paused(stage: str, inputs: Path, folder: Path, log: Path) -> subprocess.Popen:
    folder.mkdir()
    out = out_path(folder, stage)
    command = [
        sys.executable,
        "-c",
        PAUSED,
        str(folder.parent / f"{folder.name}.busy"),
        str(out),
        "--log",
        str(log),
        *args(stage, inputs, out),
    ]
    return subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)


def wait_busy(proc: subprocess.Popen, flag: Path) -> None:
    deadline = time.time() + 120
    while not flag.exists():
        assert proc.poll() is None, proc.stderr.read()
        assert time.time() < deadline, "the stage never reached its output"
        time.sleep(0.05)


@pytest.mark.parametrize("stage", STAGES)
def test_signals_leave_nothing_and_the_next_run_sweeps_a_killed_one(stage, inputs, tmp_path):
    signals = {"int": signal.SIGINT, "term": signal.SIGTERM, "kill": signal.SIGKILL}
    procs = {name: start_paused(stage, inputs, tmp_path / name, tmp_path / f"{name}.log") for name in signals}
    try:
        for name, proc in procs.items():  # all three run at once: one start-up's wait for all
            wait_busy(proc, tmp_path / f"{name}.busy")
            assert [p.name.startswith(".") for p in (tmp_path / name).iterdir()] == [True]  # the temporary
            proc.send_signal(signals[name])
        codes = {name: proc.wait(timeout=60) for name, proc in procs.items()}
    finally:
        for proc in procs.values():
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    assert codes == {"int": 130, "term": 143, "kill": -signal.SIGKILL}, {n: p.stderr.read() for n, p in procs.items()}
    for name, word in (("int", "interrupted (SIGINT)"), ("term", "terminated (SIGTERM)")):
        assert list((tmp_path / name).iterdir()) == []
        assert word in (tmp_path / f"{name}.log").read_text()
        stderr = procs[name].stderr.read()  # progress bars, then one line
        assert "Traceback" not in stderr and word in stderr.strip().splitlines()[-1], stderr
    left = [p.name for p in (tmp_path / "kill").iterdir()]
    assert len(left) == 1 and ".tmp-" in left[0], left
    out = out_path(tmp_path / "kill", stage)
    assert main(args(stage, inputs, out)) == 0  # the next run
    assert [p.name for p in (tmp_path / "kill").iterdir()] == [out.name]


def test_sigterm_mid_render_kernel_leaves_no_temporary_output(tmp_path):
    """Not paused: SIGTERM while the OpenCL render loop is busy (PoCL set up, pycolmap imported)."""
    out = tmp_path / "capture"
    proc = subprocess.Popen(
        [sys.executable, "-m", "invrender.cli", "synthesize", "room", "--out", str(out), "--spp", "100000"],
        stderr=subprocess.PIPE,
        stdout=subprocess.DEVNULL,
    )
    try:
        deadline = time.time() + 120
        while time.time() < deadline and not any(".tmp-" in p.name for p in tmp_path.iterdir()):
            time.sleep(0.2)
        time.sleep(1.0)  # inside the render loop by now
        proc.send_signal(signal.SIGTERM)
        proc.wait(timeout=60)
    finally:
        if proc.poll() is None:  # never leave a 100,000-spp render running
            proc.kill()
            proc.wait()
    assert proc.returncode == 143, proc.stderr.read()
    assert list(tmp_path.iterdir()) == [], [p.name for p in tmp_path.iterdir()]
