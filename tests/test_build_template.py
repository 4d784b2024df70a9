"""tools/build_template.py: the committed template is its output (to the last printed
decimal), and the dental warp is one-to-one.

The build reads an assets tree laid out as the shared assets (``--assets``): the fixture
:func:`assets` assembles one from the repository (the skull of tests/data/skull-yahoojapan, the ICT
head of samples/ict, the FDP table of faceforge/mpeg4/data). The warp's own properties are checked
on synthetic points.
"""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path

import numpy as np
import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]
FILES = ("cranium.obj", "mandible.obj", "landmarks.yaml", "jaw.yaml")


@pytest.fixture(scope="module")
def bt():
    spec = importlib.util.spec_from_file_location("build_template", ROOT / "tools" / "build_template.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def assets(tmp_path_factory):
    """An assets tree (as ``tools/build_template.py --assets`` reads it) of repository files."""
    root = tmp_path_factory.mktemp("assets")
    files = {"anatomy/skull-yahoojapan/skull_low_resolution.obj": "tests/data/skull-yahoojapan/skull_low_resolution.obj",
             "heads/ict/ict_face_headneck_neutral.obj": "samples/ict/ict_face_headneck_neutral.obj",
             "heads/ict/ict_face_headneck_neutral.fdp.yaml": "samples/ict/ict_face_headneck_neutral.fdp.yaml",
             "mpeg4/fdp_feature_points.csv": "faceforge/mpeg4/data/fdp_feature_points.csv"}
    for dst, src in files.items():
        (root / dst).parent.mkdir(parents=True, exist_ok=True)
        (root / dst).symlink_to(ROOT / src)
    return root


_NUMBER = re.compile(r"(-?\d+\.\d+)")


def _same_to_the_printed_digit(built: str, committed: str) -> list[str]:
    """The lines of two text files that differ other than by one unit in the last printed
    decimal of a number (the build's floating point changes in that digit from one numpy or
    scipy release to the next: 73 of 7,760 vertices moved by 1e-6 between numpy 2.3 and 2.4).
    All other text, every line and every number to its last printed decimal must agree."""
    a, b = built.splitlines(), committed.splitlines()
    if len(a) != len(b):
        return [f"{len(a)} lines built, {len(b)} committed"]
    bad = []
    for i, (x, y) in enumerate(zip(a, b)):
        px, py = _NUMBER.split(x), _NUMBER.split(y)   # text, number, text, ..., text
        same = len(px) == len(py) and px[::2] == py[::2]
        for s, t in zip(px[1::2], py[1::2]) if same else ():
            digits = max(len(s.partition(".")[2]), len(t.partition(".")[2]))
            same &= abs(float(s) - float(t)) <= 1.000001 * 10.0 ** -digits
        if not same:
            bad.append(f"line {i + 1}: {x!r} built, {y!r} committed")
    return bad


def test_the_build_reproduces_the_committed_template_to_the_printed_digit(bt, assets, tmp_path):
    summary = bt.build(assets, tmp_path)
    assert summary["dental_drop"] == 0.0
    for name in FILES:
        bad = _same_to_the_printed_digit((tmp_path / name).read_text(),
                                         (ROOT / "templates" / "skull" / name).read_text())
        assert not bad, (name, bad[:5])


def test_the_printed_digit_comparison_catches_a_real_change():
    base = "# header\nv 1.000000 -2.500000 3.250000\nf 1 2 3\n"
    assert _same_to_the_printed_digit(base, base.replace("3.250000", "3.250001")) == []
    assert _same_to_the_printed_digit(base, base.replace("3.250000", "3.250002"))
    assert _same_to_the_printed_digit(base, base.replace("f 1 2 3", "f 1 3 2"))
    assert _same_to_the_printed_digit(base, base.replace("header", "heading"))
    assert _same_to_the_printed_digit(base, base.replace("-2.500000", "2.500000"))
    assert _same_to_the_printed_digit("a: [0.5, -6.86341]", "a: [0.5, -6.863411]") == []
    assert _same_to_the_printed_digit("a: [0.5, -6.86341]", "a: [0.5, -6.86343]")
    assert _same_to_the_printed_digit(base, base + "v 0 0 0\n")


def _turned(v0, v1, f):
    def normals(v):
        t = v[f]
        return np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
    return int((np.einsum("ij,ij->i", normals(v0), normals(v1)) <= 0).sum())


def test_the_dental_warp_puts_the_incisal_edge_on_the_lips_and_folds_nothing(bt, assets, tmp_path):
    plain = bt.build(assets, tmp_path / "plain")
    warped = bt.build(assets, tmp_path / "dental", dental=True)
    fdp = yaml.safe_load((assets / "heads/ict/ict_face_headneck_neutral.fdp.yaml").read_text())["landmarks"]
    stomion = (fdp["2.2"]["position"][1] + fdp["2.3"]["position"][1]) / 2.0
    assert 1.0 < warped["dental_drop"] < bt.DENTAL_DOWN
    for bone in ("cranium", "mandible"):
        v0, f = plain[bone]
        v1, f1 = warped[bone]
        assert np.array_equal(f, f1)
        assert _turned(v0, v1, f) == 0, bone                     # one-to-one: no triangle turns over
        assert np.array_equal(v0[:, [0, 2]], v1[:, [0, 2]])      # vertical only
    jaw = yaml.safe_load((tmp_path / "dental" / "jaw.yaml").read_text())
    assert jaw["pitch_axis"] == yaml.safe_load((tmp_path / "plain" / "jaw.yaml").read_text())["pitch_axis"]
    # the incisal edge (front of the dental cut) lands on the lips' contact line, and the
    # lip landmarks then sit at the skin's own heights (no occlusal shift left)
    marks = warped["landmarks"]
    assert abs(marks["2.2"][0][1] - marks["2.3"][0][1]) < 1.0
    assert abs((marks["2.2"][0][1] + marks["2.3"][0][1]) / 2.0 - stomion) < 0.1
    # the nose base, the chin and everything above the mouth stay
    for key in ("9.15", "2.1", "4.1", "5.3", "3.7"):
        assert np.allclose(marks[key][0], plain["landmarks"][key][0], atol=0.02), key


def test_dental_warp_moves_only_its_region_and_keeps_each_vertical_line_one_to_one(bt):
    front, slope, drop = np.array([0.0, -1.8, 10.3]), 0.2, 1.6
    y = np.linspace(-9.0, 4.0, 2001)
    for z in (3.0, 4.5, 6.0, 8.0, 10.3, 12.0):
        p = np.c_[np.zeros_like(y), y, np.full_like(y, z)]
        q = bt.dental_warp(p, front, slope, drop)
        assert np.all(np.diff(q[:, 1]) > 0), z                   # strictly increasing along y
        assert np.array_equal(q[:, [0, 2]], p[:, [0, 2]])
        y_occ = front[1] + slope * (z - front[2])
        far = (y > y_occ + bt.DENTAL_UP) | (y < y_occ - bt.DENTAL_DOWN)
        assert np.array_equal(q[far], p[far]), z                 # nose and chin untouched
        if z <= bt.DENTAL_Z[0]:
            assert np.array_equal(q, p)                          # rami and condyles untouched
    edge = bt.dental_warp(front[None], front, slope, drop)[0]
    assert np.allclose(edge, front - [0.0, drop, 0.0])           # the full drop at the incisal edge
