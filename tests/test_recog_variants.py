"""tools/recog_variants.py: preset variants as FAP rows (column k = FAP k + 1) and muscles zeroed."""

import importlib.util
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]


def _tool():
    spec = importlib.util.spec_from_file_location("recog_variants", ROOT / "tools" / "recog_variants.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_variant_rows_lay_fap_numbers_over_the_preset_neutral_first():
    tool = _tool()
    fear = np.zeros(68)
    fear[52], fear[2] = 150.0, 100.0           # FAP 53 (stretch) and FAP 3 (open_jaw)
    labels, rows, zeros = tool.variant_rows({"fear": fear}, {
        "fear": ("fear", {}), "jaw": ("fear", {3: 400}), "zero": (None, {6: 150}, ("risorius_L",))})
    assert labels == ["neutral", "fear", "jaw", "zero"]
    assert rows.shape == (4, 68) and not rows[0].any()
    assert rows[1][52] == 150.0 and rows[1][2] == 100.0
    assert rows[2][2] == 400.0 and rows[2][52] == 150.0        # FAP 3 is column 2
    assert rows[3][5] == 150.0 and rows[3].sum() == 150.0
    assert zeros == [(), (), (), ("risorius_L",)]
    assert fear[2] == 100.0                                     # the preset itself untouched
    with pytest.raises(ValueError):
        tool.variant_rows({"fear": fear}, {"bad": ("fear", {1: 5})})


def test_zero_muscles_zeroes_only_the_named_muscles_of_each_row():
    tool = _tool()
    c = np.ones((3, 3))
    out = tool.zero_muscles(c, ["a", "b", "c"], [(), ("b",), ("a", "c")])
    assert out.tolist() == [[1, 1, 1], [1, 0, 1], [0, 1, 0]]
    assert c.all()
