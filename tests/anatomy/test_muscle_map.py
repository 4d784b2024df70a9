"""The default muscle map (templates/muscle_map.yaml) and its loader's validation."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import numpy as np
import pytest
import trimesh

from faceforge.anatomy.muscles.muscle_map import (BONES, MuscleSpec, SkullProjector, layers, load_muscle_map,
                                          mirrored_name)
from faceforge.anatomy.skull import load_skull
from faceforge.exceptions import TemplateError

ROOT = Path(__file__).resolve().parents[2]
MAP = ROOT / "templates" / "muscle_map.yaml"

PASSIVE = {"masseter", "fatty_tissue", "platysma"}
FIG6 = {"frontalis_inner", "frontalis_outer", "corrugator_supercilii", "levator_labii_inner",
        "levator_labii_outer", "zygomaticus_major", "risorius", "depressor_anguli", "masseter",
        "fatty_tissue", "platysma"}
BROW_DEPRESSORS = {"depressor_supercilii", "orbicularis_oculi"}   # beyond Fig. 6: they lower the brows


@pytest.fixture(scope="module")
def skull():
    return load_skull(ROOT / "templates" / "skull")


@pytest.fixture(scope="module")
def muscles(skull):
    return load_muscle_map(MAP, skull)


@pytest.fixture(scope="module")
def by_name(muscles):
    return {m.name: m for m in muscles}


def base(name):
    return name[:-2] if name.endswith(("_L", "_R")) else name


def test_31_linear_and_the_orbicularis_oris(muscles):
    """Fig. 6's 25 linear muscles, the two pairs of brow depressors, the cheek raisers and the sphincter."""
    kinds = Counter(m.type for m in muscles)
    assert kinds == {"linear": 31, "sphincter": 1}
    assert [m.name for m in muscles if m.type == "sphincter"] == ["orbicularis_oris"]
    assert len({m.name for m in muscles}) == len(muscles)


def test_figure_6_muscles_present_on_both_sides(by_name):
    for b in FIG6 | BROW_DEPRESSORS:
        assert f"{b}_L" in by_name and f"{b}_R" in by_name, b


def test_passive_support_muscles(muscles):
    for m in muscles:
        assert m.active == (base(m.name) not in PASSIVE), m.name


def test_layers_only_lie_on_deeper_layers(muscles, by_name):
    for m in muscles:
        assert m.h >= 2 and m.w >= 2 and 0 < m.thickness < 0.2
        for under in m.lies_on:
            assert under in BONES or by_name[under].layer < m.layer, (m.name, under)
    assert any(m.lies_on != ("skull",) for m in muscles), "some muscles lie on others (layers)"
    assert sorted(layers(muscles)) == [0, 1, 2, 3, 4]


def test_every_contour_point_lies_on_the_skull(skull, muscles):
    v, f, _ = skull.combined()
    mesh = trimesh.Trimesh(v, f, process=False)
    pts = np.vstack([m.points() for m in muscles])
    _, d, _ = trimesh.proximity.closest_point(mesh, pts)
    assert d.max() < 1e-6 * skull.diagonal


def test_left_muscles_on_the_left_and_mirrors_match(skull, muscles, by_name):
    tol = 0.01 * skull.diagonal
    for m in muscles:
        if m.name.endswith("_L"):
            assert (m.points()[:, 0] > 0).all(), f"{m.name} must lie on the subject's left (+X)"
            r = by_name[mirrored_name(m.name)]
            assert r.mirror_of == m.name
            assert r.lies_on == tuple(s if s in BONES else mirrored_name(s) for s in m.lies_on)
            for key in ("origin", "insertion"):
                a, b = getattr(m, key), getattr(r, key)
                assert np.abs(a * [-1, 1, 1] - b).max() < tol, (m.name, key)


def test_bones_under_each_muscle(skull, by_name):
    """Muscles on the mandible follow the jaw, those on the upper skull do not (§6)."""
    project = SkullProjector(skull)

    def bones(name):
        return set(project(by_name[name].points())[1].tolist())

    for name in ("frontalis_inner_L", "frontalis_outer_R", "corrugator_supercilii_L", "levator_labii_inner_L",
                 "levator_labii_outer_R", "depressor_supercilii_L", "orbicularis_oculi_R"):
        assert bones(name) == {0}, name
    # the zygomaticus hangs from the cheek bone; its insertion, the modiolus at the mouth
    # corner, straddles the occlusal line (both jaws)
    assert set(project(by_name["zygomaticus_major_L"].origin)[1].tolist()) == {0}
    # the masseter lies on the ramus only: a sheet whose bottom lies on bone cannot bridge
    # the sigmoid notch from the zygomatic arch without folding (templates/README.md)
    for name in ("mentalis", "depressor_labii_inferioris_L", "platysma_R", "depressor_anguli_L", "masseter_L"):
        assert bones(name) == {1}, name
    assert bones("orbicularis_oris") == {0, 1}, "the lips span both jaws"


def test_action_lines_close_the_contour(muscles):
    for m in muscles:
        a = m.action_lines()
        if m.type == "linear":
            assert np.array_equal(a["A0"][0], a["A3"][0]) and np.array_equal(a["A0"][-1], a["A1"][0])
            assert np.array_equal(a["A2"][0], a["A3"][-1]) and np.array_equal(a["A2"][-1], a["A1"][-1])
        else:
            assert np.array_equal(a["A0"], a["A2"])
            assert np.array_equal(a["A0"][0], a["A1"][0]) and np.array_equal(a["A0"][-1], a["A3"][0])
            assert len(a["A1"]) >= 3 and len(a["A3"]) >= 3


def test_sphincter_outer_loop_surrounds_the_inner(by_name):
    oo = by_name["orbicularis_oris"]
    c = oo.inner.mean(0)
    r_in = np.linalg.norm((oo.inner - c)[:, :2], axis=1).mean()
    r_out = np.linalg.norm((oo.outer - c)[:, :2], axis=1).mean()
    assert r_out > 1.5 * r_in


def test_mirrored_name_round_trip():
    for n in ("risorius_L", "risorius_R", "mentalis"):
        assert mirrored_name(mirrored_name(n)) == n
    assert mirrored_name("risorius_L") == "risorius_R"


# --------------------------------------------------------------------------- validation
GOOD = """units: template
muscles:
  - name: deep_L
    type: linear
    layer: 0
    lies_on: [skull]
    active: false
    h: 4
    w: 3
    thickness: 0.01
    origin: [{fdp: "4.3", offset: [0, 1.0, 0]}, {fdp: "4.5", offset: [0, 1.0, 0]}]
    insertion: [{fdp: "4.3", offset: [0, 0.3, 0]}, {fdp: "4.5", offset: [0, 0.3, 0]}]
  - name: top_L
    type: linear
    layer: 1
    lies_on: [skull, deep_L]
    h: 4
    w: 2
    thickness: 0.01
    origin: [[3.5, 8.0, 8.5], [5.0, 7.5, 7.5]]
    insertion: [{fdp: "4.3", offset: [0, 0.5, 0]}, {fdp: "4.5", offset: [0, 0.5, 0]}]
  - name: top_R
    mirror_of: top_L
  - name: deep_R
    mirror_of: deep_L
"""


def write(tmp_path, text):
    p = tmp_path / "map.yaml"
    p.write_text(text)
    return p


def test_small_map_resolves_landmark_points(tmp_path, skull):
    specs = load_muscle_map(write(tmp_path, GOOD), skull)
    assert [s.name for s in specs] == ["deep_L", "top_L", "top_R", "deep_R"]
    assert isinstance(specs[0], MuscleSpec)
    assert specs[2].lies_on == ("skull", "deep_R")
    assert specs[0].active is False and specs[1].active is True
    # a landmark-relative point with zero offset lands exactly on the landmark (already on bone)
    text = GOOD.replace('{fdp: "4.3", offset: [0, 1.0, 0]}', '{fdp: "2.10", offset: [0, 0, 0]}')
    spec = load_muscle_map(write(tmp_path, text), skull)[0]
    assert np.linalg.norm(spec.origin[0] - skull.landmarks["2.10"]) < 1e-6 * skull.diagonal


@pytest.mark.parametrize("old,new,pattern", [
    ("    w: 3\n", "    w: 3\n    colour: red\n", r"deep_L.*unknown key.*colour"),
    ("lies_on: [skull, deep_L]", "lies_on: [skull, deepest_L]", r"top_L.*lies_on 'deepest_L'"),
    ("    layer: 1\n", "    layer: 0\n", r"top_L.*not deeper"),
    ("    h: 4\n    w: 2\n", "    h: 4\n    w: 1\n", r"top_L.*w = 1.*>= 2"),
    ("    h: 4\n    w: 3\n", "    h: 1\n    w: 3\n", r"deep_L.*h = 1.*>= 2"),
    ('{fdp: "4.3", offset: [0, 0.5, 0]}', '{fdp: "99.1", offset: [0, 0.5, 0]}', r"top_L.*unknown FDP '99.1'"),
    ("mirror_of: top_L", "mirror_of: top_X", r"top_R.*mirror_of 'top_X'"),
    ("  - name: deep_R\n", "  - name: top_R\n", r"top_R.*duplicate"),
    ("    type: linear\n    layer: 0\n", "    type: circular\n    layer: 0\n", r"deep_L.*type"),
    ("    thickness: 0.01\n    origin: [[3.5", "    thickness: 2\n    origin: [[3.5", r"top_L.*thickness"),
    ("units: template", "units: mm", r"units"),
    ("origin: [[3.5, 8.0, 8.5], [5.0, 7.5, 7.5]]", "origin: [[3.5, 8.0, 8.5]]", r"top_L.*origin.*at least 2"),
    ("    mirror_of: top_L\n", "    mirror_of: top_L\n    h: 5\n", r"top_R.*unknown key.*h"),
    ("    w: 2\n", "    w: 2\n    max_contraction: 1.0\n", r"top_L.*max_contraction"),
])
def test_errors_name_the_file_and_the_muscle(tmp_path, skull, old, new, pattern):
    assert old in GOOD
    p = write(tmp_path, GOOD.replace(old, new, 1))
    with pytest.raises(TemplateError, match=pattern) as err:
        load_muscle_map(p, skull)
    assert str(err.value).startswith(str(p))
    assert "\n" not in str(err.value)


def test_muscle_error_carries_its_line(tmp_path, skull):
    p = write(tmp_path, GOOD.replace("    layer: 1\n", "    layer: 0\n", 1))
    with pytest.raises(TemplateError) as err:
        load_muscle_map(p, skull)
    assert err.value.line == GOOD.splitlines().index("  - name: top_L") + 1


def test_bad_yaml_and_missing_file(tmp_path, skull):
    with pytest.raises(TemplateError, match=r"map.yaml:\d+: invalid YAML"):
        load_muscle_map(write(tmp_path, "muscles: [\n  - {name: a\n"), skull)
    with pytest.raises(TemplateError, match="not found"):
        load_muscle_map(tmp_path / "nope.yaml", skull)


def test_with_points_is_the_inverse_of_points(muscles):
    """``MuscleSpec.with_points`` puts ``points()`` back into the fields they came from, for
    every template muscle (linear and sphincter), and refuses a wrong count."""
    for spec in muscles:
        moved = spec.points() * 2.0 + 1.0
        again = spec.with_points(moved)
        assert np.array_equal(again.points(), moved)
        for key in ("origin", "fibre_a", "fibre_b", "insertion", "inner", "outer"):
            assert np.array_equal(getattr(again, key), getattr(spec, key) * 2.0 + 1.0), (spec.name, key)
        with pytest.raises(ValueError, match=spec.name):
            spec.with_points(moved[:-1])


def test_max_contraction_is_kept_and_mirrored(tmp_path, skull, by_name):
    specs = load_muscle_map(write(tmp_path, GOOD.replace("    w: 2\n", "    w: 2\n    max_contraction: 0.7\n", 1)),
                            skull)
    assert [s.max_contraction for s in specs] == [None, 0.7, 0.7, None]
    assert by_name["depressor_anguli_L"].max_contraction == by_name["depressor_anguli_R"].max_contraction == 0.75


def test_depressor_anguli_draws_the_corner_down_and_out(by_name):
    """The depressor anguli runs from the mandible's lower border (below the oblique line, lateral
    of the corner) up to the modiolus: both edges of its sheet lean out as they go down, at least 5
    degrees from the vertical in the frontal plane, so it draws the corner down and out (FACS AU15).
    The first map's origin (1.8 / 3.7 cm from the chin FDP) gave a medial edge within 2 degrees of
    vertical, and on ICT's fit a muscle that pulled the corner in (docs/notes/sad20.md, dao21.md)."""
    dao = by_name["depressor_anguli_L"]
    for origin, insertion in zip(dao.origin, dao.insertion):
        fibre = origin - insertion
        assert fibre[1] < 0
        assert np.degrees(np.arctan2(fibre[0], -fibre[1])) >= 5.0


def test_the_risorius_shortens_further_than_the_default(by_name):
    """The risorius's fibres shorten by 70 % at c = 1 (the linear default 50 %): levelled on the
    fitted head (fit.level_muscles, on) its line is 3-28 % shorter than the tilted one, and at 50 %
    MediaPipe's stretch FAP (53/54 +110 MW) stopped at 70 MW with the muscle at full contraction
    (docs/notes/ris23.md)."""
    from faceforge.anatomy.muscles.linear import LINEAR_MAX_CONTRACTION

    assert by_name["risorius_L"].max_contraction == by_name["risorius_R"].max_contraction == 0.7
    assert by_name["risorius_L"].max_contraction > LINEAR_MAX_CONTRACTION
