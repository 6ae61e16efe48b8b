"""call_isolated: native work in a child process answers signals at once, keeps a time limit, and
turns a crash into an exception (issue 10, defect 3: geometry on a mesh scaled by 1e30 was still
unwrapping after 11 minutes, deferring SIGTERM)."""

import faulthandler
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

import invrender.scene.atlas as atlas
from invrender.scene.isolate import NativeFailure, call_isolated
from invrender.scene.types import SceneError


def octahedron(scale: float):
    positions = scale * np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], float)
    faces = [[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]]
    return positions, np.array(faces)


def refuse(path):
    raise SceneError(path, "faces", "a surface")


def crash():
    faulthandler.disable()  # pytest's, inherited: its report is noise here
    os.kill(os.getpid(), signal.SIGSEGV)


def test_results_and_exceptions_come_back():
    assert call_isolated(np.add, np.arange(3), 1).tolist() == [1, 2, 3]
    with pytest.raises(SceneError, match="^m.ply: faces: expected a surface$"):
        call_isolated(refuse, "m.ply")


def test_a_crash_is_an_exception():
    with pytest.raises(NativeFailure, match=r"^segv crashed \(signal 11\)$"):
        call_isolated(crash, what="segv")


def test_xatlas_hanging_on_a_huge_mesh_is_stopped_by_the_limit(monkeypatch):
    """xatlas packs the charts of an octahedron 1e30 m across forever (measured: 11 minutes)."""
    monkeypatch.setattr(atlas, "UNWRAP_LIMIT_S", (2.0, 0.0))
    started = time.monotonic()
    with pytest.raises(NativeFailure, match=r"^xatlas unwrapping 8 faces did not finish within 2 s$"):
        atlas.unwrap(*octahedron(1e30), resolution=64)
    assert time.monotonic() - started < 10
    assert atlas.unwrap(*octahedron(1.0), resolution=64).width == 64  # a sane one is quick


def test_sigterm_during_xatlas_ends_the_stage_at_once():
    code = (
        "import sys, numpy as np; from invrender.cli import install_signal_handlers\n"
        "from invrender.scene.atlas import unwrap\n"
        "install_signal_handlers(); print('busy', flush=True)\n"
        f"unwrap(np.array({octahedron(1e30)[0].tolist()}), np.array({octahedron(1)[1].tolist()}), resolution=64)\n"
    )
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline() == "busy\n"
        time.sleep(2.0)  # inside xatlas' packing by now
        proc.send_signal(signal.SIGTERM)
        signalled = time.monotonic()
        proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 143 and time.monotonic() - signalled < 5, proc.stderr.read()
