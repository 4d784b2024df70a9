"""tests/scenarios/: the slow end-to-end runs on the sample heads (fit, bind, animate,
calibrate for real). Every test here is marked ``slow`` (``-m "not slow"`` skips them)."""

from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent


def pytest_collection_modifyitems(config, items):
    for item in items:
        if HERE in Path(str(item.fspath)).resolve().parents:
            item.add_marker(pytest.mark.slow)
