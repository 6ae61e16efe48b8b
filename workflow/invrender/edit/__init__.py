"""The `edit` stage: scene edits (relight, insert an object, repaint a region, a novel camera)
applied to a scene, and to its truth when there is one, and rendered (``stage.run``); the edits
themselves are scene/edits.py, shared with the evaluation."""

from .stage import run

__all__ = ["run"]
