"""Checkpoints that resume a run bit for bit, and refuse to resume the wrong one.

A checkpoint holds the network, both optimisers and their schedules, torch's generator state, the
iteration count and the training time so far. Every random draw of an iteration is keyed by (seed,
iteration) (render/batches.py, train.py), the adjoint accumulates in fixed point and torch runs
with deterministic algorithms, so a run resumed from iteration k ends with the same weights as
one that never stopped. What it was made from is kept as two hashes: the settings (config.py) and
the atlas (texel positions), each named when it disagrees.
"""

from __future__ import annotations

import hashlib
import logging
import re
from pathlib import Path

import numpy as np
import torch

from ..scene.atomic import atomic_path
from ..scene.types import SceneError

log = logging.getLogger(__name__)
FORMAT = "invrender-milo-checkpoint"
_NAME = re.compile(r"^iter_(\d{6,})\.pt$")


def atlas_hash(positions: np.ndarray, mask: np.ndarray) -> str:
    digest = hashlib.sha256(np.ascontiguousarray(mask).tobytes())
    digest.update(np.ascontiguousarray(positions[mask], np.float32).tobytes())
    return digest.hexdigest()[:16]


def save(directory, state: dict) -> Path:
    """Write iter_<iteration>.pt atomically and delete the older ones (the newest is enough)."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    path = directory / f"iter_{state['iteration']:06d}.pt"
    with atomic_path(path) as tmp:
        torch.save({"format": FORMAT, **state}, tmp)
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


def load(path, settings: dict, settings_digest: str, atlas_digest: str) -> dict:
    """The checkpoint at `path`, or the SceneError that says why it cannot resume this run."""
    path = Path(path)
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as error:  # torch raises RuntimeError, EOFError, UnpicklingError ... for a bad file
        raise SceneError(path, "checkpoint", f"a checkpoint written by invrender milo (unreadable: {error})") from None
    if not isinstance(state, dict) or state.get("format") != FORMAT:
        raise SceneError(path, "format", f"a checkpoint written by invrender milo ({FORMAT})")
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
