"""Checkpoints that resume a run bit for bit, and refuse to resume the wrong one.

A checkpoint holds the network, both optimisers and their schedules, torch's generator state, the
iteration count and the training time so far. Every random draw of an iteration is keyed by (seed,
iteration) (render/batches.py, train.py), the adjoint accumulates in fixed point and torch runs
with deterministic algorithms, so a run resumed from iteration k ends with the same weights as
one that never stopped. The file format and its checks are scene/checkpoints.py's; this module
names milo's format.
"""

from __future__ import annotations

from ..scene import checkpoints as _checkpoints
from ..scene.checkpoints import atlas_hash, checkpoints, latest

__all__ = ["FORMAT", "WRITER", "atlas_hash", "checkpoints", "latest", "save", "load", "resume"]

FORMAT = "invrender-milo-checkpoint"
WRITER = "invrender milo"


def save(directory, state: dict):
    return _checkpoints.save(directory, state, FORMAT)


def load(path, settings: dict, settings_digest: str, atlas_digest: str) -> dict:
    return _checkpoints.load(path, settings, settings_digest, atlas_digest, FORMAT, WRITER)


def resume(directory, mode: str, settings: dict, digests) -> dict | None:
    return _checkpoints.resume(directory, mode, settings, digests, FORMAT, WRITER)
