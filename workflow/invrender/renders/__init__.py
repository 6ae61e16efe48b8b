"""The `render` stage: every camera of a scene directory rendered to EXR + PNG preview, with its
per-pixel variance and AOVs, into results/{scene}/renders/ (``stage.run``)."""

from .stage import run

__all__ = ["run"]
