"""The evaluate tests' helper module (truths.py) imports by name, as tests/conftest.py arranges
for the other folders' helpers."""

import sys
from pathlib import Path

HERE = str(Path(__file__).parent)
if HERE not in sys.path:
    sys.path.insert(0, HERE)
