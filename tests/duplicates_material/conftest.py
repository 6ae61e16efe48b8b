"""The session's small duplicates captures (material_capture.py says what they are)."""

from __future__ import annotations

import pytest
from material_capture import capture_config, material_inputs

from invrender.synthesize import stage as synthesize


@pytest.fixture(scope="session")
def captures(tmp_path_factory) -> dict:
    """{copies: (capture dir, stage inputs)} for 6 and 2 copies (16 spp photographs)."""
    root = tmp_path_factory.mktemp("material_captures")
    out = {}
    for count in (6, 2):
        capture = root / f"box-{count}"
        synthesize.run("duplicates", capture, capture_config(count), spp=16)
        out[count] = (capture, material_inputs(capture, root / f"inputs-{count}"))
    return out
