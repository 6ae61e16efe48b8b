"""The `import` stage: textured OBJ files, a lat-long environment map and cameras in, a scene
directory (format v2) out (``stage.run``). The package has a trailing underscore because
``import`` is a Python keyword (PEP 8's rule for such names); the verb is `invrender import`."""

from .stage import run

__all__ = ["run"]
