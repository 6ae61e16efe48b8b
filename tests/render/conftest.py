"""tests/ has no __init__ files: make the helper modules next to this file (chi2.py)
importable from the tests in this directory."""

import sys
from pathlib import Path

_HERE = str(Path(__file__).resolve().parent)
if _HERE not in sys.path:
    sys.path.insert(0, _HERE)
