"""Every failure ends in one line for the user and the same line in --log; a bug's traceback goes
to the log, not the terminal (issue 10, defect 8: a read-only output parent gave a PermissionError
traceback, and after any traceback the --log file was empty)."""

import os
import re
import subprocess
import sys

import pytest

import invrender.cameras.stage
from invrender.cli import main
from invrender.scene.cameras import write_colmap

CAMERA_LINE = re.compile(r"^\S+ \S+ invrender ERROR ")


@pytest.fixture
def sparse(tmp_path):
    from objscene import camera

    write_colmap(tmp_path / "sparse", [camera()])
    return tmp_path / "sparse"


def test_an_output_that_cannot_be_written_is_one_line(sparse, tmp_path):
    """/sys refuses new directories even to root (as a read-only parent does to a user)."""
    log = tmp_path / "run.log"
    run = subprocess.run(
        [
            sys.executable,
            "-m",
            "invrender.cli",
            "--log",
            str(log),
            "cameras",
            str(sparse),
            "--out",
            "/sys/invrender-test/out",
        ],
        capture_output=True,
        text=True,
    )
    assert run.returncode == 2
    lines = run.stderr.strip().splitlines()
    assert (
        len(lines) == 1
        and "/sys: output: expected a directory where /sys/invrender-test/out can be written" in lines[0]
    ), run.stderr
    assert log.read_text().strip() == lines[0]


def test_a_bug_is_one_line_naming_the_log_which_has_the_traceback(sparse, tmp_path, capsys, monkeypatch):
    def broken(*args, **kwargs):
        raise ZeroDivisionError("a bug")

    monkeypatch.setattr(invrender.cameras.stage, "write_colmap", broken)
    log = tmp_path / "run.log"
    assert main(["--log", str(log), "cameras", str(sparse), "--out", str(tmp_path / "out")]) == 1
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and CAMERA_LINE.match(lines[0]), lines
    assert lines[0].endswith(f"invrender cameras failed: ZeroDivisionError: a bug (a bug; the traceback is in {log})")
    text = log.read_text()
    assert text.startswith(lines[0] + "\nTraceback (most recent call last):") and "in broken" in text
    assert not (tmp_path / "out").exists()

    assert main(["-v", "cameras", str(sparse), "--out", str(tmp_path / "out")]) == 1  # -v: here too
    err = capsys.readouterr().err
    assert "Traceback (most recent call last):" in err and "in broken" in err
    where = re.search(r"the traceback is in (\S+)\)", err)[1]  # no --log: a file of its own
    assert "in broken" in open(where).read()
    os.remove(where)


def test_a_log_that_cannot_be_opened_is_one_line(sparse, tmp_path, capsys):
    (tmp_path / "file").write_text("x")
    assert (
        main(["--log", str(tmp_path / "file" / "run.log"), "cameras", str(sparse), "--out", str(tmp_path / "out")]) == 2
    )
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("invrender: --log: ") and str(tmp_path / "file") in lines[0]
