"""The `segment` stage: the copies of one object in one photograph as an instance-id mask,
instances.json and an overlay (``stage.run``); backends in opencv.py and provided.py."""

from .stage import run

__all__ = ["run"]
