"""The `gradients` stage: d(image loss)/d(map) of the starting scene, one EXR and one signed PNG
preview per map (``stage.run``)."""

from .stage import run

__all__ = ["run"]
