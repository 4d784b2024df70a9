"""The muscle map around the mouth follows the skin's lips (faceforge.fit.mouth)."""

from __future__ import annotations

import numpy as np
import pytest

from faceforge.fit.mouth import MouthField, mouth_field

from .heads import SAMPLES


def test_a_uniform_shift_is_exact_inside_and_fades_to_nothing():
    """With one shift at every source the Shepard mean is that shift: in full within
    ``inner`` of the centre, none beyond ``outer``, and a monotone fade between."""
    rng = np.random.default_rng(3)
    src = rng.normal(scale=0.3, size=(6, 3))
    delta = np.array([0.1, -0.4, 0.0])
    f = MouthField(src, np.tile(delta, (6, 1)), np.zeros(3), 1.0, 2.0, 0.5)
    near = rng.normal(scale=0.2, size=(50, 3))
    near = near[np.linalg.norm(near, axis=1) < 1.0]
    np.testing.assert_allclose(f.displacement(near), np.tile(delta, (len(near), 1)), atol=1e-15)
    far = np.array([[2.0, 0.0, 0.0], [0.0, -3.0, 0.0], [0.0, 0.0, 50.0]])
    assert np.array_equal(f.displacement(far), np.zeros((3, 3)))
    ray = np.linspace(1.0, 2.0, 21)[:, None] * np.array([[0.0, 1.0, 0.0]])
    frac = f.displacement(ray)[:, 1] / delta[1]
    assert frac[0] == pytest.approx(1.0) and frac[-1] == 0.0 and np.all(np.diff(frac) < 0)
    np.testing.assert_allclose(f(far), far)


def test_mouth_field_shifts_in_the_frontal_plane_only():
    """Each lip FDP's bone point is shifted toward the skin's in x and y only (the depth is the
    projection's); heads without two lip FDPs or the corners get no field."""
    skin = {"8.3": [2.0, 0.0, 1.0], "8.4": [-2.0, 0.0, 1.0], "2.2": [0.0, 0.1, 1.2], "2.3": [0.0, -0.1, 1.2]}
    bone = {"8.3": [2.0, 0.5, 0.0], "8.4": [-2.0, 0.5, 0.0], "2.2": [0.0, 0.8, 0.1], "2.3": [0.0, 0.6, 0.2]}
    f = mouth_field(bone, skin)
    np.testing.assert_allclose(f.shifts[:, 2], 0.0)
    np.testing.assert_allclose(f.shifts[:, 1], [-0.7, -0.7, -0.5, -0.5])       # 2.2, 2.3, 8.3, 8.4
    assert f.inner == pytest.approx(1.2 * 2.0) and f.outer == pytest.approx(2.4 * 2.0)
    assert mouth_field({"2.2": bone["2.2"]}, skin) is None
    assert mouth_field(bone, {k: v for k, v in skin.items() if k not in ("8.3", "8.4")}) is None


@pytest.fixture(scope="module")
def mouth_fits(template):
    """``fits(name)``: the sample head fitted with ``mouth_follows_lips`` (off by default)."""
    from faceforge.fit.files import fit_files

    cache = {}

    def fits(name):
        if name not in cache:
            mesh = SAMPLES[name]
            cache[name] = fit_files(mesh, mesh.with_name(mesh.stem + ".fdp.yaml"), template,
                                    {"mouth_follows_lips": True})
        return cache[name]
    return fits


@pytest.mark.parametrize("name", sorted(SAMPLES))
def test_the_sphincter_surrounds_the_mouth_opening(mouth_fits, fitted, name):
    """On each sample head the orbicularis oris' inner loop (the lips' contact line in the
    template) lies around the skin's mouth opening: its vertical span holds the opening and
    its centre lies within a fifth of the mouth's half-width of it (it lay 0.9-2.2 cm above
    without the mouth's shift, which the report gives: the default fit)."""
    plain = fitted(name)
    result, report, extra = mouth_fits(name)
    lm = dict(zip(extra["landmarks"].ids, np.asarray(extra["landmarks"].positions)))
    opening = 0.5 * (lm["2.2"][1] + lm["2.3"][1])
    half = 0.5 * np.linalg.norm(lm["8.3"] - lm["8.4"])
    spec = next(s for s in extra["template"].specs if s.name == "orbicularis_oris")
    inner = result.muscle_points["orbicularis_oris"][:len(spec.inner)]
    assert inner[:, 1].min() < opening < inner[:, 1].max()
    assert abs(inner[:, 1].mean() - opening) < 0.2 * half
    assert report["mouth"]["follows_lips"] and 0.01 < report["mouth"]["max_shift_rel"] < 0.15
    off = plain[0].muscle_points["orbicularis_oris"][:len(spec.inner)]
    assert not plain[1]["mouth"]["follows_lips"] and abs(off[:, 1].mean() - opening) > 0.3 * half


def test_weights_run_from_the_origin_to_the_insertion(template):
    """On every template muscle: a linear muscle's origin takes none of the mouth's shift, its
    insertion all of it, and its fibres' inner points a weight that grows toward the
    insertion; a sphincter takes all of it. The built sheets agree: row 0 lies at the
    origin, row h - 1 at the insertion."""
    from faceforge.fit.mouth import point_weights, sheet_weights

    built = {name: (rest, hw) for name, rest, _, hw, _ in template.muscles}
    for spec in template.specs:
        w = point_weights(spec)
        assert w.shape == (len(spec.points()),) and np.all((0 <= w) & (w <= 1))
        sheet = sheet_weights(spec.type, spec.h, spec.w)
        rest, hw = built[spec.name]
        assert sheet.shape == (len(rest),) and hw == spec.h * spec.w
        if spec.type != "linear":
            assert np.all(w == 1) and np.all(sheet == 1)
            continue
        k = len(spec.origin)
        assert np.all(w[:k] == 0) and np.all(w[len(w) - len(spec.insertion):] == 1)
        for fibre in (w[k:k + len(spec.fibre_a)], w[k + len(spec.fibre_a):k + len(spec.fibre_a) + len(spec.fibre_b)]):
            assert np.all((0 < fibre) & (fibre < 1)) and np.all(np.diff(fibre) > 0), spec.name
        o = spec.origin.mean(axis=0)
        bottom = rest[:hw].reshape(spec.h, spec.w, 3)
        assert np.linalg.norm(bottom[0].mean(0) - o) < np.linalg.norm(bottom[-1].mean(0) - o), spec.name
        assert np.all(np.diff(sheet[:hw].reshape(spec.h, spec.w)[:, 0]) > 0)
