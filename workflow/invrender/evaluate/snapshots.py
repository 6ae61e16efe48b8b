"""Training snapshots: the six maps every K iterations, with the iteration and the seconds of training.

A snapshot is ``iter_XXXXXX.npz`` (the training stage writes them) with keys kd (H, W, 3),
ks (H, W, 3), ka (H, W), ke (H, W, 3), kw (H, W), kg (6, N, N, 3), float32, on the recovered
atlas, and the scalars ``iteration`` and ``wall_time`` (seconds of training up to it).
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from ..scene.types import ATLAS_MAPS, MAP_CHANNELS, Maps, SceneError

__all__ = ["SNAPSHOT_PATTERN", "list_snapshots", "load_snapshot"]

SNAPSHOT_PATTERN = re.compile(r"^iter_(\d{6,})\.npz$")


def list_snapshots(directory) -> list[Path]:
    """The snapshot files of ``directory`` in iteration order."""
    directory = Path(directory)
    if not directory.is_dir():
        raise SceneError(directory, "snapshots", "a directory of iter_XXXXXX.npz files")
    found = [p for p in directory.iterdir() if SNAPSHOT_PATTERN.match(p.name)]
    return sorted(found, key=lambda p: int(SNAPSHOT_PATTERN.match(p.name).group(1)))


def load_snapshot(path, atlas_shape: tuple[int, int]) -> tuple[Maps, int, float]:
    """(maps, iteration, wall_time seconds), checked: every key there, shapes on the recovered
    atlas, finite values."""
    path = Path(path)
    try:
        data = np.load(path)
    except (OSError, ValueError) as error:
        raise SceneError(path, "file", f"a readable .npz snapshot ({error})") from None
    with data:
        keys = (*ATLAS_MAPS, "kg", "iteration", "wall_time")
        missing = [k for k in keys if k not in data]
        if missing:
            raise SceneError(path, ", ".join(missing), "the snapshot keys " + ", ".join(keys))
        maps = {}
        for name in ATLAS_MAPS:
            expected = (*atlas_shape, 3) if MAP_CHANNELS[name] == 3 else tuple(atlas_shape)
            maps[name] = _checked(path, name, data[name], expected)
        kg = data["kg"]
        if kg.ndim != 4 or kg.shape[0] != 6 or kg.shape[1] != kg.shape[2] or kg.shape[3] != 3:
            raise SceneError(path, "kg", f"a (6, N, N, 3) cube map, got shape {kg.shape}")
        maps["kg"] = _checked(path, "kg", kg, kg.shape)
        iteration, wall_time = data["iteration"], data["wall_time"]
        if iteration.size != 1 or wall_time.size != 1 or not np.isfinite(float(wall_time)):
            raise SceneError(path, "iteration, wall_time", "two finite scalars")
        return Maps(**maps), int(iteration), float(wall_time)


def _checked(path: Path, name: str, array: np.ndarray, expected: tuple) -> np.ndarray:
    if array.shape != tuple(expected):
        raise SceneError(path, name, f"shape {tuple(expected)} (the recovered atlas), got {array.shape}")
    if not np.all(np.isfinite(array)):
        raise SceneError(path, name, "finite values")
    return np.asarray(array, np.float32)
