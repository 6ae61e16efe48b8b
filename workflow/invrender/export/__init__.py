"""USD export of a scene directory, and its import back.

- ``export_usd(scene_dir, out_dir, ...)`` (``stage.py``): ``scene.usda`` (and ``scene.usdc`` on
  request) with ``textures/`` beside it: UsdGeom meshes with ``st``, UsdPreviewSurface materials,
  UsdLux lights, UsdGeom cameras, native instancing of duplicates.
- ``import_usd(usd_path, out_dir, ...)`` (``importer.py``): such a stage, perhaps edited in another
  tool, back into a scene directory.

One concept per module: ``geometry`` (meshes), ``instancing`` (prototypes from poses),
``materials`` (UsdPreviewSurface and textures), ``roughness`` (Beckmann ka <-> UsdPreviewSurface
roughness, and the mapping's measured error), ``lights`` (DomeLight, mesh lights), ``cameras``
(COLMAP <-> UsdGeom.Camera), ``schema`` (the ``invrender:`` attributes that make the round trip
exact), ``check`` (the validators usdchecker runs). docs/export.md is the user's guide.
"""

from __future__ import annotations

__all__ = ["export_usd", "import_usd", "validate_usd"]


def export_usd(*args, **kwargs):
    from .stage import export_usd as run

    return run(*args, **kwargs)


def import_usd(*args, **kwargs):
    from .importer import import_usd as run

    return run(*args, **kwargs)


def validate_usd(*args, **kwargs):
    from .check import validate_usd as run

    return run(*args, **kwargs)
