"""FAPU on real landmarks and the FAP displacement vectors."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from faceforge.exceptions import LandmarkError
from faceforge.mpeg4 import Fapu, fap_displacement, fapu_from_landmarks

ROOT = Path(__file__).resolve().parents[2]
ICT = ROOT / "samples" / "ict" / "ict_face_headneck_neutral.fdp.yaml"
#: the three sample heads and a MakeHuman identity (tests/data/makehuman-identities)
FDP_FILES = sorted(ROOT.glob("samples/*/*.fdp.yaml")) + sorted(ROOT.glob("tests/data/makehuman-identities/*.fdp.yaml"))


def load_positions(path: Path) -> dict[str, np.ndarray]:
    """FDP -> position; pupils of eyeless meshes have ``vertex: null`` but a position."""
    data = yaml.safe_load(path.read_text())
    return {str(k): np.asarray(v["position"], dtype=float) for k, v in data["landmarks"].items()}


@pytest.fixture(scope="module")
def ict():
    return load_positions(ICT)


def test_ict_fapu_follow_the_formulas(ict):
    fapu = fapu_from_landmarks(ict)
    assert fapu.es0 == ict["3.5"][0] - ict["3.6"][0]
    assert fapu.ens0 == (ict["3.5"][1] + ict["3.6"][1]) / 2 - ict["9.15"][1]
    assert fapu.mns0 == ict["9.15"][1] - ict["2.2"][1]
    assert fapu.mw0 == ict["8.3"][0] - ict["8.4"][0]
    both_eyes = ((ict["3.1"][1] - ict["3.3"][1]) + (ict["3.2"][1] - ict["3.4"][1])) / 2
    assert fapu.irisd0 == pytest.approx(both_eyes, rel=1e-12)


def test_ict_fapu_match_the_asset_readme(ict):
    """README: ES0 ~ 6.39, ENS0 ~ 4.82, MNS0 ~ 2.12, MW0 ~ 5.07 cm.

    MNS0 and MW0 agree to 1 %. The README's ES0 / ENS0 were evidently taken from other pupil
    points (ENS0 = 4.82 matches the front of the ICT eyeball's iris, which is not part of
    this eyeless mesh); the landmark file's pupils (centre of the eye opening) give 6.45 and
    4.68, within 1 % and 3.5 %.
    """
    fapu = fapu_from_landmarks(ict)
    assert fapu.mns0 == pytest.approx(2.12, rel=0.01)
    assert fapu.mw0 == pytest.approx(5.07, rel=0.01)
    assert fapu.es0 == pytest.approx(6.39, rel=0.01)
    assert fapu.ens0 == pytest.approx(4.82, rel=0.035)
    units = fapu.as_dict()
    assert units["MW"] == fapu.mw0 / 1024 and units["AU"] == 1e-5


@pytest.mark.parametrize(
    "path", FDP_FILES, ids=lambda p: p.parent.name
)
def test_every_sample_head_gives_positive_fapu(path):
    assert len(FDP_FILES) == 4
    fapu = fapu_from_landmarks(load_positions(path), source=path)
    per_fap = fapu.per_fap()
    assert np.all(np.isnan(per_fap[:2])) and np.all(per_fap[2:] > 0)


def test_fapu_scale_with_the_face_and_ignore_translation(ict):
    base = fapu_from_landmarks(ict)
    moved = fapu_from_landmarks({k: 2.5 * v + np.array([3.0, -1.0, 7.0]) for k, v in ict.items()})
    for name in ("es0", "ens0", "mns0", "mw0", "irisd0"):
        assert getattr(moved, name) == pytest.approx(2.5 * getattr(base, name), rel=1e-12)


def test_missing_fdps_are_named(ict):
    partial = {k: v for k, v in ict.items() if k not in ("9.15", "8.4")}
    with pytest.raises(LandmarkError) as err:
        fapu_from_landmarks(partial, source="head.fdp.yaml")
    message = str(err.value)
    assert message.startswith("head.fdp.yaml: ") and "8.4" in message and "9.15" in message
    no_lids = {k: v for k, v in ict.items() if k not in ("3.1", "3.2")}
    with pytest.raises(LandmarkError, match="IRISD0 needs 3.1 and 3.3"):
        fapu_from_landmarks(no_lids)
    one_eye = {k: v for k, v in ict.items() if k not in ("3.2",)}
    assert fapu_from_landmarks(one_eye).irisd0 == pytest.approx(one_eye["3.1"][1] - one_eye["3.3"][1])


def test_mirrored_landmarks_are_rejected(ict):
    mirrored = {k: v * np.array([-1.0, 1.0, 1.0]) for k, v in ict.items()}
    with pytest.raises(LandmarkError, match="ES0"):
        fapu_from_landmarks(mirrored)


def test_fap_displacement_directions_and_sizes():
    fapu = Fapu(es0=6.0, ens0=4.0, mns0=2.0, mw0=5.0, irisd0=1.0)
    fdp, d = fap_displacement(3, 1024, fapu)  # open_jaw: chin down by one MNS0
    assert fdp == "2.1"
    np.testing.assert_allclose(d, [0.0, -2.0, 0.0])
    fdp, d = fap_displacement("stretch_l_cornerlip_o", 512, fapu)  # subject's left = +X
    assert fdp == "8.3"
    np.testing.assert_allclose(d, [2.5, 0.0, 0.0])
    fdp, d = fap_displacement("raise_r_o_eyebrow", -100, fapu)
    assert fdp == "4.6"
    np.testing.assert_allclose(d, [0.0, -100 * 4.0 / 1024, 0.0])
    fdp, d = fap_displacement("thrust_jaw", 10, fapu)
    np.testing.assert_allclose(d, [0.0, 0.0, 10 * 2.0 / 1024])
    # linear in the value
    _, a = fap_displacement(53, 37.0, fapu)
    _, b = fap_displacement(53, -74.0, fapu)
    np.testing.assert_allclose(b, -2.0 * a)


@pytest.mark.parametrize("fap", [1, 2, 23, 29, 47, 48])
def test_fap_displacement_rejects_non_translations(fap):
    with pytest.raises(ValueError, match=f"FAP {fap} "):
        fap_displacement(fap, 1.0, Fapu(1, 1, 1, 1, 1))
