"""Maps files: the six maps as one .npz with the iteration and the seconds of training behind them.

The milo stage writes one every K iterations (``snapshots/iter_XXXXXX.npz``, read by evaluate for
its accuracy-against-time curve) and its final maps (``maps.npz``, read by bake). Keys kd (H, W, 3),
ks (H, W, 3), ka (H, W), ke (H, W, 3), kw (H, W), kg (6, N, N, 3), float32, on the recovered
atlas, and the scalars ``iteration`` and ``wall_time`` (seconds of training up to it).
"""

from __future__ import annotations

import re
import zipfile
from pathlib import Path

import numpy as np

from .atomic import atomic_path
from .types import ATLAS_MAPS, MAP_CHANNELS, Maps, SceneError

__all__ = [
    "SNAPSHOT_PATTERN",
    "SNAPSHOT_KEYS",
    "list_snapshots",
    "drop_snapshots_after",
    "check_snapshot",
    "load_snapshot",
    "write_snapshot",
]

SNAPSHOT_PATTERN = re.compile(r"^iter_(\d{6,})\.npz$")
SNAPSHOT_KEYS = (*ATLAS_MAPS, "kg", "iteration", "wall_time")
HEADER_READERS = {(1, 0): np.lib.format.read_array_header_1_0, (2, 0): np.lib.format.read_array_header_2_0}


def list_snapshots(directory) -> list[Path]:
    """The snapshot files of ``directory`` in iteration order."""
    directory = Path(directory)
    if not directory.is_dir():
        raise SceneError(directory, "snapshots", "a directory of iter_XXXXXX.npz files")
    found = [p for p in directory.iterdir() if SNAPSHOT_PATTERN.match(p.name)]
    return sorted(found, key=lambda p: int(SNAPSHOT_PATTERN.match(p.name).group(1)))


def drop_snapshots_after(directory, iteration: int) -> None:
    """A fresh run (iteration 0) or a resumed one owns the snapshots after its start: an earlier,
    longer run's would otherwise reach evaluate's accuracy-against-time curve."""
    directory = Path(directory)
    for path in list_snapshots(directory) if directory.is_dir() else []:
        if int(SNAPSHOT_PATTERN.match(path.name).group(1)) > iteration:
            path.unlink()


def _expected_shape(name: str, atlas_shape) -> tuple | None:
    if name in ATLAS_MAPS:
        return (*atlas_shape, 3) if MAP_CHANNELS[name] == 3 else tuple(atlas_shape)
    return None


def check_snapshot(path, atlas_shape: tuple[int, int]) -> None:
    """Every key there with the right shape, read from the arrays' headers only (a stage refuses
    a bad snapshot before its work, without loading every snapshot's maps at once)."""
    path = Path(path)
    try:
        with zipfile.ZipFile(path) as archive:
            shapes = {}
            for member in archive.namelist():
                with archive.open(member) as handle:
                    reader = HEADER_READERS.get(np.lib.format.read_magic(handle))
                    if reader is None:
                        raise ValueError(f"{member}: an .npy format version numpy can read")
                    shapes[member.removesuffix(".npy")] = reader(handle)[0]
    except (OSError, ValueError, zipfile.BadZipFile) as error:
        raise SceneError(path, "file", f"a readable .npz snapshot ({error})") from None
    missing = [k for k in SNAPSHOT_KEYS if k not in shapes]
    if missing:
        raise SceneError(path, ", ".join(missing), "the snapshot keys " + ", ".join(SNAPSHOT_KEYS))
    for name in ATLAS_MAPS:
        if shapes[name] != _expected_shape(name, atlas_shape):
            raise SceneError(
                path, name, f"shape {_expected_shape(name, atlas_shape)} (the recovered atlas), got {shapes[name]}"
            )
    kg = shapes["kg"]
    if len(kg) != 4 or kg[0] != 6 or kg[1] != kg[2] or kg[3] != 3:
        raise SceneError(path, "kg", f"a (6, N, N, 3) cube map, got shape {kg}")


def load_snapshot(path, atlas_shape: tuple[int, int]) -> tuple[Maps, int, float]:
    """(maps, iteration, wall_time seconds), checked: every key there, shapes on the recovered
    atlas, finite values."""
    path = Path(path)
    try:
        data = np.load(path)
    except (OSError, ValueError) as error:
        raise SceneError(path, "file", f"a readable .npz snapshot ({error})") from None
    with data:
        missing = [k for k in SNAPSHOT_KEYS if k not in data]
        if missing:
            raise SceneError(path, ", ".join(missing), "the snapshot keys " + ", ".join(SNAPSHOT_KEYS))
        maps = {name: _checked(path, name, data[name], _expected_shape(name, atlas_shape)) for name in ATLAS_MAPS}
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


def write_snapshot(path, maps: Maps, iteration: int, wall_time: float) -> None:
    """Write the maps file atomically (a killed run leaves none that looks complete)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    arrays = {name: np.asarray(getattr(maps, name), np.float32) for name in (*ATLAS_MAPS, "kg")}
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as handle:
            np.savez_compressed(handle, **arrays, iteration=int(iteration), wall_time=float(wall_time))
