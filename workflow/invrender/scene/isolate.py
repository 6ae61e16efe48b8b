"""Native work in a child process, so that it cannot hold up signals, hang or crash the stage.

A native call that holds the GIL (xatlas' charting and packing, up to minutes, forever on some
degenerate meshes) delays Python's signal handlers until it returns: SIGTERM from a scheduler
waited, and the temporary output stayed. ``call_isolated`` runs the call in a forked child (the
arguments are shared by fork, not copied through a pipe) while the parent waits in Python: SIGINT
and SIGTERM are answered at once (the child is killed as the exception unwinds), a time limit is
kept, and a crash in native code (xatlas segfaults on some meshes) is an exception, not the end
of the stage.
"""

from __future__ import annotations

import ctypes
import logging
import logging.handlers
import multiprocessing
import os
import pickle
import signal
import time
import traceback

__all__ = ["call_isolated", "NativeFailure"]


class NativeFailure(RuntimeError):
    """The isolated call crashed, or ran past its time limit."""


def _end_with_parent() -> None:
    """Linux: the child gets SIGKILL when the parent dies (even by SIGKILL), rather than working on."""
    try:
        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass


class _Pipe:
    """QueueHandler's queue: log records go to the parent, ready for pickling."""

    def __init__(self, send):
        self.send = send

    def put_nowait(self, record):
        self.send.send(("log", record))


def _forward_logs(send) -> None:
    """The child's log records go to the parent, which hands them to its own handlers (the
    terminal, --log, a test's caplog): written once, in order, where the caller looks."""
    for name in ("", "invrender"):
        logger = logging.getLogger(name)
        for handler in list(logger.handlers):
            logger.removeHandler(handler)
    logging.getLogger().addHandler(logging.handlers.QueueHandler(_Pipe(send)))


def _child(send, parent: int, fn, args, kwargs) -> None:
    # The parent answers signals; the child just ends (Ctrl-C reaches the whole process group).
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    _end_with_parent()
    if os.getppid() != parent:  # the parent died before the line above
        os._exit(1)
    _forward_logs(send)
    try:
        answer = (True, fn(*args, **kwargs))
    except BaseException as error:  # sent to the parent, which raises it
        error.add_note("In the child process:\n" + "".join(traceback.format_exception(error)).rstrip())
        answer = (False, error)
        try:
            pickle.loads(pickle.dumps(error))
        except Exception:  # an exception class that does not survive pickling
            answer = (False, NativeFailure("".join(traceback.format_exception(error)).strip()))
    send.send(("answer", answer))
    send.close()


def call_isolated(fn, *args, limit_s: float | None = None, what: str | None = None, **kwargs):
    """``fn(*args, **kwargs)`` in a forked child: its result, or its exception raised here.

    ``limit_s``: seconds after which the child is killed and NativeFailure raised. Without fork
    (not POSIX) the call runs in this process.
    """
    if "fork" not in multiprocessing.get_all_start_methods():
        return fn(*args, **kwargs)
    what = what or getattr(fn, "__name__", "native call")
    context = multiprocessing.get_context("fork")
    receive, send = context.Pipe(duplex=False)
    child = context.Process(target=_child, args=(send, os.getpid(), fn, args, kwargs))
    started = time.monotonic()
    child.start()
    send.close()
    try:
        while True:
            while not receive.poll(0.05):  # short waits: a signal's handler runs between them
                if limit_s is not None and time.monotonic() - started > limit_s:
                    raise NativeFailure(f"{what} did not finish within {limit_s:.0f} s")
            try:
                kind, message = receive.recv()
            except EOFError:  # the child ended without answering
                child.join()
                code = child.exitcode
                how = f"signal {-code}" if code is not None and code < 0 else f"exit status {code}"
                raise NativeFailure(f"{what} crashed ({how})") from None
            if kind == "answer":
                ok, value = message
                break
            logging.getLogger(message.name).handle(message)
    finally:
        if child.is_alive():
            child.kill()
        child.join()
        receive.close()
    if ok:
        return value
    raise value
