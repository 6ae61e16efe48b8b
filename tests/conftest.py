"""Shared by all tests: the helper modules under tests/ import by name, and kernel builds go to
a cache private to the test session unless INVRENDER_CACHE says otherwise."""

import os
import sys
from pathlib import Path

HERE = Path(__file__).parent
for helper_dir in (HERE, HERE / "render", HERE / "geometry", HERE / "import_", HERE / "fuzz"):
    if str(helper_dir) not in sys.path:
        sys.path.insert(0, str(helper_dir))
