"""Fixtures of the workflow tests; the helpers they share are in workflow_helpers.py (a module
name of its own: tests/render has a conftest too)."""

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))

from workflow_helpers import TEST_CONFIG  # noqa: E402


@pytest.fixture(scope="session")
def test_config() -> dict:
    import yaml

    return yaml.safe_load(TEST_CONFIG.read_text())
