"""The `cameras` stage: every later stage reads one camera format, a COLMAP text model."""

from __future__ import annotations

import logging
from pathlib import Path

from ..scene.atomic import check_output
from ..scene.cameras import read_cameras, write_colmap
from ..scene.types import Camera, SceneError

log = logging.getLogger(__name__)


def run(source, out_dir) -> list[Camera]:
    """A capture's cameras (COLMAP model directory, text or binary, or a transforms.json), read by
    ``read_cameras`` and written to ``out_dir`` as a COLMAP text model (atomically). Returns the
    cameras."""
    check_output(out_dir, "cameras")
    cameras = read_cameras(source)
    if not cameras:
        raise SceneError(Path(source), "(cameras)", "at least one posed camera")
    write_colmap(out_dir, cameras)
    log.info("%s: %d camera(s) -> %s", source, len(cameras), out_dir)
    return cameras
