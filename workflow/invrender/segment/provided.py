"""The `provided` backend: instance masks from any tool, read and checked.

an id image   one PNG, 8 or 16 bit, single channel: 0 = background, each other value one
              instance (the form `segment` itself writes, and most tools can export)
a folder      one PNG per instance (single channel, nonzero = the instance), in name order;
              a pixel two files claim stays with the first
a table       optional, with an id image: JSON ({"instances": [{"id": ...}]}, a list of
              such objects, or a list of ids) or CSV with an `id` column, listing the ids
              the image may hold. An id beyond it stops: the image and the table disagree,
              so one of them is not what the user meant.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np

from ..scene.images import read_mask
from ..scene.types import SceneError

__all__ = ["read_provided", "read_table"]


def _check_size(path: Path, mask: np.ndarray, size: tuple[int, int], image) -> None:
    height, width = mask.shape
    if (width, height) != size:
        raise SceneError(
            path,
            "size",
            f"the photograph's size {size[0]} x {size[1]} ({image}), got {width} x {height}",
        )


def _ids_from_json(path: Path) -> list:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as error:
        raise SceneError(path, "(file)", f"a JSON instance table ({error})") from None
    rows = data.get("instances") if isinstance(data, dict) else data
    if not isinstance(rows, list):
        raise SceneError(path, "instances", 'a list of instances ({"id": ...}) or of ids')
    return [row.get("id") if isinstance(row, dict) else row for row in rows]


def _ids_from_csv(path: Path) -> list:
    try:
        with open(path, newline="", encoding="utf-8") as handle:
            rows = list(csv.DictReader(handle))
    except (UnicodeDecodeError, csv.Error) as error:
        raise SceneError(path, "(file)", f"a CSV instance table ({error})") from None
    if not rows or "id" not in rows[0]:
        raise SceneError(path, "id", "a CSV header with an `id` column and a row per instance")
    return [row["id"] for row in rows]


def read_table(path) -> set[int]:
    """The instance ids a table lists (JSON or CSV), each a positive integer."""
    path = Path(path)
    if not path.is_file():
        raise SceneError(path, "(file)", "an existing instance table (JSON or CSV)")
    suffix = path.suffix.lower()
    if suffix not in (".json", ".csv"):
        raise SceneError(path, "(file)", f"a .json or .csv instance table, got {suffix or 'no suffix'}")
    ids = _ids_from_json(path) if suffix == ".json" else _ids_from_csv(path)
    out = set()
    for value in ids:
        try:
            number = int(str(value).strip())
        except ValueError:
            number = None
        if number is None or number < 1 or number > 65535 or str(number) != str(value).strip():
            raise SceneError(path, "id", f"instance ids as integers 1 .. 65535, got {value!r}")
        out.add(number)
    return out


def _read_folder(folder: Path, size, image) -> tuple[np.ndarray, list[str]]:
    files = sorted(p for p in folder.iterdir() if p.suffix.lower() == ".png" and p.is_file())
    if not files:
        raise SceneError(folder, "(folder)", "one PNG per instance (nonzero = the instance); it holds none")
    ids = np.zeros((size[1], size[0]), np.uint16)
    for number, path in enumerate(files, 1):
        mask = read_mask(path)
        _check_size(path, mask, size, image)
        ids[(mask > 0) & (ids == 0)] = number
    return ids, [p.name for p in files]


def read_provided(masks, size: tuple[int, int], image, table=None) -> tuple[np.ndarray, dict[int, str | int]]:
    """An id image or a folder of per-instance PNGs as (H, W) uint16 ids (as found, not yet
    renumbered) and, per id, where it came from (the id image's value, or the file's name).
    ``size`` is the photograph's (width, height), ``image`` its path for messages."""
    masks = Path(masks)
    if masks.is_dir():
        if table is not None:
            raise SceneError(table, "table", f"no table with a folder of masks ({masks}): each file is one instance")
        ids, names = _read_folder(masks, size, image)
        return ids, {i: name for i, name in enumerate(names, 1)}
    ids = read_mask(masks)
    _check_size(masks, ids, size, image)
    found = sorted(int(i) for i in np.unique(ids) if i)
    if table is not None:
        listed = read_table(table)
        beyond = [i for i in found if i not in listed]
        if beyond:
            raise SceneError(
                masks,
                "instance ids",
                f"only the ids {Path(table).name} lists ({_short(sorted(listed))}), found {_short(beyond)} beyond it",
            )
    return ids, {i: i for i in found}


def _short(ids: list[int], most: int = 8) -> str:
    text = ", ".join(map(str, ids[:most]))
    return text + (f" and {len(ids) - most} more" if len(ids) > most else "") if ids else "none"
