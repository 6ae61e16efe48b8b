"""The asset library (PSDR-Room section 4, the object stage): procedural furniture, user
OBJ/PLY/USD models, and their retrieval by silhouette and depth descriptors of multi-view
renders. A library like render/: no stage, no rule; docs/assets.md.

    from invrender import assets
    library = assets.library(user_dirs)             # [Asset], unit-normalised, named parts
    matches = assets.retrieve(mask, depth, library, k=5, focal=f, up=floor_normal_in_camera)
    yaw = assets.yaw_from_view(matches[0].azimuth_deg, object_centre, camera_centre)
"""

from .asset import Asset
from .furniture import CATEGORIES, bundled, furniture

# The function `library` takes the package attribute of its module `library.py` (bound after the
# module's import, and never re-bound): `assets.library(...)` calls it, and
# `from invrender.assets.library import library` still finds the module in sys.modules.
from .library import library, read_model, user_assets
from .retrieval import Match, library_descriptors, retrieve, yaw_from_view

__all__ = [
    "Asset",
    "CATEGORIES",
    "Match",
    "bundled",
    "furniture",
    "library",
    "library_descriptors",
    "read_model",
    "retrieve",
    "user_assets",
    "yaw_from_view",
]
