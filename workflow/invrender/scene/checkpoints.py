"""Checkpoints of a training stage: resume bit for bit, refuse to resume the wrong run.

A checkpoint is one torch file ``iter_<iteration>.pt`` holding whatever state the stage needs
(its parameters, optimisers, schedules, iteration count, training time) beside two hashes of
what it was made from: the settings and the atlas (texel positions), each named when it
disagrees. Only the newest is kept. Each stage names its own format (``invrender-milo-checkpoint``,
``invrender-duplicates-material-checkpoint``), so one stage never resumes another's file.
"""

from __future__ import annotations

import hashlib
import logging
import re
from pathlib import Path

import numpy as np

from .atomic import atomic_path
from .types import SceneError

__all__ = ["RESUME", "check_resume", "atlas_hash", "save", "checkpoints", "load", "latest", "resume"]

log = logging.getLogger(__name__)
RESUME = ("never", "always", "auto")
_NAME = re.compile(r"^iter_(\d{6,})\.pt$")


def check_resume(mode: str, where: str) -> None:
    """`--resume mode` is one of RESUME, or a SceneError naming `where` (the command's flag)."""
    if mode not in RESUME:
        raise SceneError(where, "resume", f"one of {', '.join(RESUME)}, got {mode!r}")


def atlas_hash(positions: np.ndarray, mask: np.ndarray) -> str:
    digest = hashlib.sha256(np.ascontiguousarray(mask).tobytes())
    digest.update(np.ascontiguousarray(positions[mask], np.float32).tobytes())
    return digest.hexdigest()[:16]


def save(directory, state: dict, format: str) -> Path:
    """Write iter_<iteration>.pt atomically and delete the older ones (the newest is enough)."""
    import torch

    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    path = directory / f"iter_{state['iteration']:06d}.pt"
    with atomic_path(path) as tmp:
        torch.save({"format": format, **state}, tmp)
    for old in checkpoints(directory):
        if old != path:
            old.unlink(missing_ok=True)
    return path


def checkpoints(directory) -> list[Path]:
    """The checkpoints in `directory`, oldest first."""
    directory = Path(directory)
    if not directory.is_dir():
        return []
    return sorted(p for p in directory.iterdir() if _NAME.match(p.name))


def load(path, settings: dict, settings_digest: str, atlas_digest: str, format: str, writer: str) -> dict:
    """The checkpoint at `path`, or the SceneError that says why it cannot resume this run.
    `writer` names the command that writes `format` ("invrender milo")."""
    import torch

    path = Path(path)
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as error:  # torch raises RuntimeError, EOFError, UnpicklingError ... for a bad file
        raise SceneError(path, "checkpoint", f"a checkpoint written by {writer} (unreadable: {error})") from None
    if not isinstance(state, dict) or state.get("format") != format:
        raise SceneError(path, "format", f"a checkpoint written by {writer} ({format})")
    if state["settings_hash"] != settings_digest:
        differ = sorted(k for k in settings if state["settings"].get(k) != settings[k])
        raise SceneError(
            path,
            "settings",
            f"the settings of this run; it was made with other values of {', '.join(differ) or 'the settings'} "
            "(start afresh, or run with the settings it was made with)",
        )
    if state["atlas_hash"] != atlas_digest:
        raise SceneError(
            path, "atlas", "the atlas of this run (geometry/atlas.npz); it was made for another mesh or atlas"
        )
    return state


def latest(directory) -> Path | None:
    found = checkpoints(directory)
    return found[-1] if found else None


def resume(directory, mode: str, settings: dict, digests, format: str, writer: str) -> dict | None:
    """The state to continue from under `--resume mode` (RESUME), or None to start afresh (then
    the directory's stale checkpoints are deleted): "always" refuses a missing, corrupt or
    mismatched checkpoint, "auto" starts afresh instead, "never" always does."""
    directory = Path(directory)
    path = latest(directory)
    if mode == "never" or (path is None and mode == "auto"):
        for stale in checkpoints(directory):
            stale.unlink()
        return None
    if path is None:
        raise SceneError(directory, "checkpoint", "a checkpoint to resume from (--resume always); there is none")
    try:
        state = load(path, settings, *digests, format, writer)
    except SceneError as error:
        if mode == "always":
            raise
        log.warning("%s: not resuming: %s; training from the start", writer, error)
        return resume(directory, "never", settings, digests, format, writer)
    log.info("%s: resuming from %s (iteration %d)", writer, path, int(state["iteration"]))
    return state
