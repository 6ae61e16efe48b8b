"""Atomic outputs: a stage never leaves a partial file or directory that looks complete, and never
replaces anything that is not its own earlier output.

Both helpers hand out a hidden temporary name beside the target (so the final rename stays on
one file system and is atomic), rename it onto the target when the ``with`` block succeeds, and
delete it when the block raises (including KeyboardInterrupt and the CLI's SystemExit on SIGTERM).

    with atomic_path("out/image.exr") as tmp:
        write_something(tmp)            # tmp keeps the suffix: ".../.image.tmp-<host>-<pid>-<rand>.exr"

    with atomic_dir("results/scene", kind="scene") as tmp:
        (tmp / "scene.json").write_text(...)

Ownership: every directory ``atomic_dir`` writes holds a marker file, ``.invrender-output``,
naming its kind ("renders", "geometry", ...). ``check_output`` accepts as a target only a new
path, an empty directory, or a directory whose marker names the same kind; an existing file or
any other directory is refused with a SceneError before anything is touched. A stage calls
``check_output`` first (so the user hears it before the work), ``atomic_dir`` checks again.

Stale temporaries: the temporary name carries the writing host and process id. A process killed
by SIGKILL (or a power cut) cannot clean up; the next write of the same target removes the
temporaries whose process on this host no longer exists.
"""

from __future__ import annotations

import hashlib
import os
import re
import secrets
import shutil
import signal
import socket
import threading
from collections.abc import Callable
from contextlib import contextmanager
from pathlib import Path

from .types import SceneError

__all__ = ["atomic_path", "atomic_dir", "check_output", "claim_dir", "MARKER"]

MARKER = ".invrender-output"  # inside every directory atomic_dir writes: its kind, one line


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


def _host() -> str:
    # Results may sit on a file system shared by cluster nodes: a pid means something only on
    # the host that wrote it, so the name says which host that was (8 hex digits of its name).
    return hashlib.sha1(socket.gethostname().encode()).hexdigest()[:8]


def _split(path: Path) -> tuple[str, str]:
    suffix = "".join(path.suffixes[-1:])
    return (path.name[: len(path.name) - len(suffix)] if suffix else path.name), suffix


def _temp_name(path: Path, role: str = "tmp", suffix: str = "") -> Path:
    stem = _split(path)[0] if suffix else path.name
    return path.parent / f".{stem}.{role}-{_host()}-{os.getpid()}-{secrets.token_hex(4)}{suffix}"


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process
        return True
    try:  # a zombie (dead, not yet reaped: an orphan where PID 1 does not reap) is gone too
        return Path(f"/proc/{pid}/stat").read_text().rpartition(")")[2].split()[0] != "Z"
    except (OSError, IndexError):
        return True


def sweep_stale(path, suffix: str = "") -> list[Path]:
    """Remove the temporaries of ``path`` left by processes of this host that no longer exist."""
    path = Path(path)
    stem = _split(path)[0] if suffix else path.name
    pattern = re.compile(rf"\.{re.escape(stem)}\.(?:tmp|old)-([0-9a-f]{{8}})-(\d+)-[0-9a-f]{{8}}{re.escape(suffix)}")
    removed = []
    try:
        entries = list(path.parent.iterdir())
    except OSError:
        return removed
    host = _host()
    for entry in entries:
        match = pattern.fullmatch(entry.name)
        if match and match[1] == host and int(match[2]) != os.getpid() and not _alive(int(match[2])):
            _remove(entry)
            removed.append(entry)
    return removed


def _kind_of(directory: Path) -> str | None:
    try:
        return (directory / MARKER).read_text(encoding="utf-8").strip()
    except (OSError, UnicodeDecodeError):
        return None


def _check_parent(path: Path) -> None:
    """The output's nearest existing ancestor is a directory where this process can create it:
    found before the work (by making and removing a hidden directory there, which also answers
    for root on a read-only or special file system), not when the finished output is renamed."""
    parent = path.absolute().parent
    while not parent.exists() and parent != parent.parent:
        parent = parent.parent
    if not parent.is_dir():
        raise SceneError(parent, "output", f"a directory to hold {path}; it is a file")
    probe = _temp_name(parent / path.name)
    try:
        probe.mkdir()
        probe.rmdir()
    except OSError as error:
        raise SceneError(
            parent, "output", f"a directory where {path} can be written ({error.strerror or error})"
        ) from None


def check_output(path, kind: str, recognise: Callable[[Path], bool] | None = None) -> Path:
    """Refuse an output path that holds something a stage of ``kind`` did not write.

    Directories (``recognise`` None): a new path, an empty directory, or a directory whose
    marker names ``kind``. Files (``recognise`` given): a new path, or an existing file that
    ``recognise(path)`` says is this stage's own output. Anything else raises SceneError,
    naming the path and what was expected, and nothing is touched.
    """
    path = Path(path)
    wanted = (
        f"a new path or an earlier {kind} file"
        if recognise
        else f"a new path, an empty directory or an earlier {kind} directory of invrender"
    )
    if path.is_symlink():
        raise SceneError(path, "output", f"{wanted}, not a symbolic link (remove it or choose another --out)")
    _check_parent(path)
    if not path.exists():
        return path
    if recognise is not None:
        if path.is_file() and recognise(path):
            return path
        what = "a directory" if path.is_dir() else "a file that is not one"
        raise SceneError(path, "output", f"{wanted}; it is {what}, which would be lost (choose another --out)")
    if not path.is_dir():
        raise SceneError(
            path, "output", f"{wanted}; it is an existing file, which would be lost (choose another --out)"
        )
    found = _kind_of(path)
    if found == kind or not any(path.iterdir()):
        return path
    holds = f"its {MARKER} says {found!r}" if found else f"it holds files and no {MARKER}"
    raise SceneError(path, "output", f"{wanted}; {holds}, so replacing it would lose them (choose another --out)")


@contextmanager
def _signals_held():
    """SIGINT and SIGTERM that arrive during the block are recorded and acted on when it ends.

    Python runs signal handlers in the main thread whichever thread the signal reached, so a
    handler that only records is reliable in a process with other threads (PoCL's, execnet's);
    blocking the signal with pthread_sigmask would hold it in this thread only."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    pending = []
    previous = {
        signum: signal.signal(signum, lambda number, frame: pending.append(number))
        for signum in (signal.SIGINT, signal.SIGTERM)
    }
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
        if pending:
            handler = previous[pending[0]]
            if callable(handler):
                handler(pending[0], None)
            elif handler == signal.SIG_DFL:
                signal.raise_signal(pending[0])


def claim_dir(path, kind: str) -> Path:
    """A directory a long-running stage fills file by file (each file with ``atomic_path``), so
    that a resumed run finds what the killed one left: checked as ``check_output`` does, then made
    and marked as ``kind``'s."""
    path = check_output(path, kind)
    path.mkdir(parents=True, exist_ok=True)
    if _kind_of(path) != kind:
        (path / MARKER).write_text(kind + "\n", encoding="utf-8")
    return path


@contextmanager
def atomic_path(path, fsync: bool = True, kind: str | None = None, recognise: Callable[[Path], bool] | None = None):
    """Yield a temporary path beside ``path``; rename it onto ``path`` on success.

    The temporary name is hidden (leading dot) and keeps the target's suffix, so writers
    that choose a format by extension still work. Nothing is created in advance: the
    caller creates the file (with the usual permissions). If the block raises, the
    temporary file is deleted and ``path`` is left as it was. A stage's own output file
    passes ``kind`` and ``recognise`` (see ``check_output``): then an existing file that is not
    its own is refused, and temporaries left by killed runs are swept first.
    """
    path = Path(path)
    if kind is not None:
        check_output(path, kind, recognise)
    path.parent.mkdir(parents=True, exist_ok=True)
    suffix = _split(path)[1]
    if kind is not None:
        sweep_stale(path, suffix)
    tmp = _temp_name(path, suffix=suffix)
    try:
        yield tmp
        if fsync and tmp.is_file():
            _fsync_file(tmp)
        if kind is not None:
            check_output(path, kind, recognise)
        os.replace(tmp, path)
    except BaseException:
        _remove(tmp)
        raise
    if fsync:
        _fsync_dir(path.parent)


@contextmanager
def atomic_dir(path, kind: str, fsync: bool = True):
    """Yield a fresh directory ``.<name>.tmp-<host>-<pid>-<rand>``; make it ``path`` on success.

    ``path`` must pass ``check_output(path, kind)``: new, empty, or an earlier output of the
    same kind, which is then replaced whole: it is first renamed aside, the new directory
    renamed in, then the old one deleted. Between those two renames ``path`` briefly does not
    exist, which never looks like a complete output. If the block raises, the temporary
    directory is deleted and ``path`` is left as it was.
    """
    path = Path(path)
    check_output(path, kind)
    path.parent.mkdir(parents=True, exist_ok=True)
    sweep_stale(path)
    while True:
        tmp = _temp_name(path)
        try:
            tmp.mkdir()  # honours the umask, unlike tempfile.mkdtemp (0700)
            break
        except FileExistsError:
            continue
    old, done = None, False
    try:
        (tmp / MARKER).write_text(kind + "\n", encoding="utf-8")
        yield tmp
        if fsync:
            for root, _, files in os.walk(tmp):
                for name in files:
                    _fsync_file(Path(root) / name)
        check_output(path, kind)  # whatever appeared there during the work is not lost either
        with _signals_held():  # a signal between the two renames would leave no output at all
            if path.exists():
                old = _temp_name(path, "old")
                os.replace(path, old)
            try:
                os.replace(tmp, path)
            except BaseException:
                if old is not None:
                    os.replace(old, path)
                raise
            done = True
    except BaseException:
        # A signal held during the renames arrives as they end: the new output stands then.
        _remove(old if done and old is not None else tmp)
        raise
    if fsync:
        _fsync_dir(path.parent)
    if old is not None:
        _remove(old)
