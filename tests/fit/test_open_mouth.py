"""A head whose mouth is open at rest is not the MPEG-4 neutral: the fit says so
(fit.open_mouth_warn, docs/notes/robust19.md)."""

from __future__ import annotations

import numpy as np
import pytest

from faceforge.fit.files import lip_gap_ratio

from .heads import SAMPLES


def _points(name):
    from faceforge.io.landmarks import read_landmarks
    from faceforge.io.mesh import load_mesh

    mesh = SAMPLES[name]
    v, _, _ = load_mesh(mesh)
    raw = read_landmarks(mesh.with_name(mesh.stem + ".fdp.yaml"))
    return {f: (v[i] if i >= 0 else p) for f, i, p in zip(raw.ids, raw.vertex, raw.position)}


def _default_limit():
    from faceforge.io.config import load_default

    return float(load_default().tree["fit"]["open_mouth_warn"])


def test_lip_gap_ratio_is_the_inner_lips_distance_over_the_mouth_width():
    pts = {"2.2": [0, 1.0, 0], "2.3": [0, 0.0, 0], "8.3": [2.0, 0.5, 0], "8.4": [-2.0, 0.5, 0]}
    assert lip_gap_ratio(pts) == pytest.approx(0.25)
    assert lip_gap_ratio({k: v for k, v in pts.items() if k != "2.3"}) is None


@pytest.mark.parametrize("name", sorted(SAMPLES))
def test_the_samples_closed_mouths_stay_under_the_default_limit(name):
    limit = _default_limit()
    assert 0 < lip_gap_ratio(_points(name)) < limit


def test_an_open_mouth_is_over_it():
    pts = _points("makehuman")
    pts["2.3"] = np.asarray(pts["2.3"]) - [0, 0.12, 0]       # the lower lip 1.2 cm down (MakeHuman: decimetres)
    assert lip_gap_ratio(pts) > _default_limit()
