"""atomic_path / atomic_dir: outputs appear whole or not at all."""

import pytest

from invrender.scene.atomic import atomic_dir, atomic_path


def test_atomic_path_success(tmp_path):
    target = tmp_path / "sub" / "out.exr"
    with atomic_path(target) as tmp:
        assert tmp.parent == target.parent and tmp.suffix == ".exr" and tmp != target
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


def test_atomic_dir_replaces_whole(tmp_path):
    target = tmp_path / "scene"
    target.mkdir()
    (target / "stale.txt").write_text("stale")
    with atomic_dir(target) as tmp:
        assert tmp.name.startswith("scene.tmp-") and tmp.is_dir()
        (tmp / "new.txt").write_text("new")
        assert (target / "stale.txt").exists()
    assert sorted(p.name for p in target.iterdir()) == ["new.txt"]
    assert [p.name for p in tmp_path.iterdir()] == ["scene"]


def test_atomic_dir_failure_leaves_no_partial_directory(tmp_path):
    target = tmp_path / "scene"
    with pytest.raises(KeyboardInterrupt):
        with atomic_dir(target) as tmp:
            (tmp / "half.txt").write_text("x")
            raise KeyboardInterrupt
    assert list(tmp_path.iterdir()) == []
