"""atomic_path / atomic_dir: outputs appear whole or not at all, replace only their own kind of
output, and sweep what killed runs left behind."""

import os
import subprocess
import sys

import pytest

from invrender.scene.atomic import MARKER, atomic_dir, atomic_path, check_output
from invrender.scene.types import SceneError


def test_atomic_path_success(tmp_path):
    target = tmp_path / "sub" / "out.exr"
    with atomic_path(target) as tmp:
        assert tmp.parent == target.parent and tmp.suffix == ".exr" and tmp != target
        assert tmp.name.startswith(".out.tmp-")
        tmp.write_text("data")
        assert not target.exists()
    assert target.read_text() == "data"
    assert sorted(p.name for p in target.parent.iterdir()) == ["out.exr"]


def test_atomic_path_failure_keeps_old_and_leaves_nothing(tmp_path):
    target = tmp_path / "out.txt"
    target.write_text("old")
    with pytest.raises(RuntimeError):
        with atomic_path(target) as tmp:
            tmp.write_text("half written")
            raise RuntimeError("boom")
    assert target.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["out.txt"]


def test_atomic_path_of_a_stage_refuses_a_file_it_did_not_write(tmp_path):
    target = tmp_path / "features.json"
    target.write_text("data\n")
    with pytest.raises(SceneError, match="features.json: output: expected a new path or an earlier features file"):
        with atomic_path(target, kind="features", recognise=lambda p: p.read_text() == "ours\n") as tmp:
            tmp.write_text("ours\n")
    assert target.read_text() == "data\n" and [p.name for p in tmp_path.iterdir()] == ["features.json"]
    target.write_text("ours\n")
    with atomic_path(target, kind="features", recognise=lambda p: p.read_text() == "ours\n") as tmp:
        tmp.write_text("ours\n")
    assert [p.name for p in tmp_path.iterdir()] == ["features.json"]


def test_atomic_dir_replaces_its_own_kind_whole(tmp_path):
    target = tmp_path / "scene"
    with atomic_dir(target, kind="scene") as tmp:
        (tmp / "stale.txt").write_text("stale")
    assert (target / MARKER).read_text() == "scene\n"
    with atomic_dir(target, kind="scene") as tmp:
        assert tmp.name.startswith(".scene.tmp-") and tmp.is_dir()
        (tmp / "new.txt").write_text("new")
        assert (target / "stale.txt").exists()
    assert sorted(p.name for p in target.iterdir()) == [MARKER, "new.txt"]
    assert [p.name for p in tmp_path.iterdir()] == ["scene"]


def test_atomic_dir_failure_leaves_no_partial_directory(tmp_path):
    target = tmp_path / "scene"
    with pytest.raises(KeyboardInterrupt):
        with atomic_dir(target, kind="scene") as tmp:
            (tmp / "half.txt").write_text("x")
            raise KeyboardInterrupt
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("existing", ["file", "foreign", "other_kind", "symlink"])
def test_atomic_dir_refuses_what_it_did_not_write(tmp_path, existing):
    """Issue 10, defect 1: `--out f.txt` replaced the file with a directory."""
    target = tmp_path / "out"
    if existing == "file":
        target.write_text("data\n")
    elif existing == "symlink":
        target.symlink_to(tmp_path)
    else:
        target.mkdir()
        (target / "mine.txt").write_text("data\n")
        if existing == "other_kind":
            (target / MARKER).write_text("scene\n")
    before = {p: (p.read_bytes() if p.is_file() else None) for p in tmp_path.rglob("*") if not p.is_symlink()}
    with pytest.raises(
        SceneError,
        match=r"out: output: expected a new path, an empty directory or an earlier "
        r"renders directory of invrender",
    ):
        with atomic_dir(target, kind="renders") as tmp:
            (tmp / "x").write_text("x")
    after = {p: (p.read_bytes() if p.is_file() else None) for p in tmp_path.rglob("*") if not p.is_symlink()}
    assert after == before


def test_atomic_dir_accepts_an_empty_directory(tmp_path):
    (tmp_path / "out").mkdir()
    assert check_output(tmp_path / "out", "renders") == tmp_path / "out"
    with atomic_dir(tmp_path / "out", kind="renders") as tmp:
        (tmp / "a").write_text("a")
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == [MARKER, "a"]


def test_temporaries_of_dead_processes_are_swept(tmp_path):
    """A SIGKILLed writer leaves its temporary; the next write of the same target removes it,
    and leaves a live writer's temporary and other targets' temporaries alone."""
    code = (
        "import os, sys; from invrender.scene.atomic import atomic_dir, atomic_path\n"
        "d = atomic_dir(sys.argv[1] + '/out', kind='renders'); tmp = d.__enter__()\n"
        "p = atomic_path(sys.argv[1] + '/f.json', kind='features', recognise=bool); p.__enter__().write_text('x')\n"
        "os.kill(os.getpid(), 9)"
    )
    subprocess.run(
        [sys.executable, "-c", code, str(tmp_path)], env=os.environ | {"PYTHONPATH": os.pathsep.join(sys.path)}
    )
    dead = sorted(p.name for p in tmp_path.iterdir())
    assert len(dead) == 2 and dead[0].startswith(".f.tmp-") and dead[1].startswith(".out.tmp-"), dead
    with atomic_dir(tmp_path / "other", kind="renders") as tmp:  # another target: not its business
        assert len(list(tmp_path.glob(".out.tmp-*"))) == 1
    live = tmp_path / f".out.tmp-{tmp.name.split('-')[1]}-{os.getppid()}-0123abcd"  # our parent lives
    live.mkdir()
    with atomic_dir(tmp_path / "out", kind="renders") as tmp:
        (tmp / "a").write_text("a")
    with atomic_path(tmp_path / "f.json", kind="features", recognise=bool) as tmp:
        tmp.write_text("y")
    assert sorted(p.name for p in tmp_path.iterdir()) == [live.name, "f.json", "other", "out"]


def test_a_signal_during_the_renames_waits_for_them(tmp_path, monkeypatch):
    """Ctrl-C between renaming the old output aside and the new one in would leave neither."""
    import signal

    import invrender.scene.atomic as atomic

    target = tmp_path / "out"
    with atomic_dir(target, kind="renders") as tmp:
        (tmp / "a").write_text("old")
    real = os.replace

    def replace_then_interrupt(source, destination):
        real(source, destination)
        os.kill(os.getpid(), signal.SIGINT)

    monkeypatch.setattr(atomic.os, "replace", replace_then_interrupt)
    with pytest.raises(KeyboardInterrupt):
        with atomic_dir(target, kind="renders") as tmp:
            (tmp / "a").write_text("new")
    assert (target / "a").read_text() == "new"
    assert [p.name for p in tmp_path.iterdir()] == ["out"]
