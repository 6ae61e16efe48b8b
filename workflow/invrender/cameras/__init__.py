"""The `cameras` stage: a capture's cameras (COLMAP text or binary, transforms.json) as one COLMAP
text model (``stage.run``); reading and writing the formats is scene/cameras.py."""

from .stage import run

__all__ = ["run"]
