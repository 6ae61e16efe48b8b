"""Atomic outputs: a stage never leaves a partial file or directory that looks complete.

Both helpers hand out a temporary name in the same directory as the target (so the final
rename stays on one file system and is atomic), rename it onto the target when the ``with``
block succeeds, and delete it when the block raises (including KeyboardInterrupt).

    with atomic_path("out/image.exr") as tmp:
        write_something(tmp)            # tmp keeps the suffix: ".../.image.tmp-1a2b3c4d.exr"

    with atomic_dir("results/scene") as tmp:
        (tmp / "scene.json").write_text(...)
"""

from __future__ import annotations

import os
import secrets
import shutil
from contextlib import contextmanager
from pathlib import Path

__all__ = ["atomic_path", "atomic_dir"]


def _fsync_file(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _fsync_dir(path: Path) -> None:
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:  # some file systems do not fsync directories
        pass
    finally:
        os.close(fd)


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        try:
            path.unlink()
        except FileNotFoundError:
            pass


@contextmanager
def atomic_path(path, fsync: bool = True):
    """Yield a temporary path beside ``path``; rename it onto ``path`` on success.

    The temporary name is hidden (leading dot) and keeps the target's suffix, so writers
    that choose a format by extension still work. Nothing is created in advance: the
    caller creates the file (with the usual permissions). If the block raises, the
    temporary file is deleted and ``path`` is left as it was.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    suffix = "".join(path.suffixes[-1:])
    stem = path.name[: len(path.name) - len(suffix)] if suffix else path.name
    tmp = path.parent / f".{stem}.tmp-{secrets.token_hex(4)}{suffix}"
    try:
        yield tmp
        if fsync and tmp.is_file():
            _fsync_file(tmp)
        os.replace(tmp, path)
    except BaseException:
        _remove(tmp)
        raise
    if fsync:
        _fsync_dir(path.parent)


@contextmanager
def atomic_dir(path, fsync: bool = True):
    """Yield a fresh empty directory ``<path>.tmp-xxxxxxxx``; make it ``path`` on success.

    An existing ``path`` (file or directory) is replaced whole: it is first renamed aside,
    the new directory renamed in, then the old one deleted. Between those two renames
    ``path`` briefly does not exist, which never looks like a complete output. If the
    block raises, the temporary directory is deleted and ``path`` is left as it was.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    while True:
        tmp = path.parent / f"{path.name}.tmp-{secrets.token_hex(4)}"
        try:
            tmp.mkdir()  # honours the umask, unlike tempfile.mkdtemp (0700)
            break
        except FileExistsError:
            continue
    try:
        yield tmp
        if fsync:
            for root, _, files in os.walk(tmp):
                for name in files:
                    _fsync_file(Path(root) / name)
        old = None
        if path.exists() or path.is_symlink():
            old = path.parent / f"{path.name}.old-{secrets.token_hex(4)}"
            os.replace(path, old)
        try:
            os.replace(tmp, path)
        except BaseException:
            if old is not None:
                os.replace(old, path)
            raise
    except BaseException:
        _remove(tmp)
        raise
    if fsync:
        _fsync_dir(path.parent)
    if old is not None:
        _remove(old)
