"""The `synthesize` stage: parametric ground-truth scenes and their rendered captures (demo data).

- ``make_room(config)``: a room for the multiview (MILO) mode (``room.py``).
- ``make_duplicates(config)``: copies of one object at known poses for the duplicates mode
  (``duplicates.py``).
- ``make_room_photo(config)``: one photograph of a furnished room with depth, panoptic ids and
  truth for the room mode (``room_photo.py``, written by its ``write_room_capture``).
- ``write_capture(scene, metadata, out_dir, renderer_factory, spp, seed)``: render and write
  ``capture/`` in the user input format with the ground truth beside it (``capture.py``).
- ``stage.run(kind, out_dir, config, spp, seed)``: the three together, what the CLI calls.
"""

from __future__ import annotations

from .capture import write_capture
from .duplicates import DUPLICATES_DEFAULTS, make_duplicates
from .room import ROOM_DEFAULTS, make_room
from .room_photo import ROOM_PHOTO_DEFAULTS, make_room_photo
from .stage import KINDS, run

__all__ = [
    "KINDS",
    "run",
    "make_room",
    "make_duplicates",
    "write_capture",
    "ROOM_DEFAULTS",
    "DUPLICATES_DEFAULTS",
    "make_room_photo",
    "ROOM_PHOTO_DEFAULTS",
]
