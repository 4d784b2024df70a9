"""FAP -> contractions + jaw: the mapping file, its arithmetic and its invariants."""

from pathlib import Path

import numpy as np
import pytest

from faceforge.animation.fap_mapping import (JawLevers, entry_drive, expression_faps, fap_controls,
                                           load_fap_mapping, mapping_from_dict, mapping_to_dict,
                                           response_curve, save_fap_mapping, viseme_faps,
                                           viseme_weights, with_entry)
from faceforge.exceptions import FaceforgeError, TemplateError
from faceforge.mpeg4 import EXPRESSION_CODES, N_FAPS, VISEME_CODES

ROOT = Path(__file__).resolve().parents[2]
MAPPING = ROOT / "templates" / "fap_mapping.yaml"
FAPU = {k: v / 1024 for k, v in {"MNS": 0.2, "MW": 0.5, "ENS": 0.45, "ES": 0.6, "IRISD": 0.1}.items()}
FAPU["AU"] = 1e-5
LEVERS = JawLevers(pitch=0.9, yaw=0.9)


@pytest.fixture(scope="module")
def mapping():
    return load_fap_mapping(MAPPING)


def frames(**values):
    f = np.zeros((1, N_FAPS))
    for k, v in values.items():
        f[0, int(k[1:]) - 1] = v
    return f


def test_every_requested_fap_group_is_mapped(mapping):
    mapped = set(mapping.mapped_faps().tolist())
    required = {3, 14, 15, *range(4, 14), 16, 17, *range(51, 61), *range(31, 43)}
    assert required <= mapped
    assert set(mapping.expressions) == set(EXPRESSION_CODES)
    assert set(mapping.visemes) == set(VISEME_CODES)


def test_no_preset_lowers_the_middle_brow_with_the_inner_and_outer(mapping):
    # FAP 33/34 down recruits the inner brow's and the outer brow's depressors together and
    # calibrates to both at full contraction; a muscle takes its largest request, so a preset that
    # also asks 31/35 got the inner brow 3x and the outer 5x what it asked (ICT anger: a ridged
    # glabella, 47 folded edges; docs/notes/folds.md "the middle brow's saturated drive")
    for name, row in mapping.expressions.items():
        for middle, inner, outer in ((33, 31, 35), (34, 32, 36)):
            if row[inner - 1] < 0 or row[outer - 1] < 0:
                assert row[middle - 1] >= 0, (name, middle)



def test_sadness_is_1_4_15_the_corners_down_with_no_borrowed_stretch(mapping):
    # sadness is 1+4+15: the inner brows raised and drawn together, the corners down. The outer brows
    # are lowered less than the inner are raised (no outer lowering in the prototype; sad20). The
    # depressor anguli, running from the mandible's lower border up and in to the modiolus, draws the
    # corners down AND out itself (templates/muscle_map.yaml); sad20 borrowed the outward part from the
    # lip stretch (AU20, fear's), which this preset no longer asks (docs/notes/dao21.md)
    sad = mapping.expressions["sadness"]
    for side in (0, 1):
        inner, outer, squeeze = 31 + side, 35 + side, 37 + side
        assert sad[inner - 1] > 0 and sad[squeeze - 1] > 0
        assert abs(sad[outer - 1]) <= 2 * sad[inner - 1]
    for corner, stretch in ((59, 53), (60, 54), (12, 6), (13, 7)):
        assert sad[corner - 1] < 0
        assert sad[stretch - 1] == 0


def test_fear_differs_from_surprise_as_facs_says(mapping):
    # fear (1+2+4+5+20+26) and surprise (1+2+5+26) share the raised brows, the raised upper lids
    # and the dropped jaw; fear adds the brows drawn together (AU4, corrugator), the lips stretched
    # sideways (AU20), and its lower lids are tense and drawn up where surprise's are let down
    # (Ekman & Friesen); its upper lids and jaw open less. Without these the face-reading
    # benchmark read fear as surprise on every head (docs/notes/recog12.md)
    fear, surprise = mapping.expressions["fear"], mapping.expressions["surprise"]
    for side in (0, 1):
        inner, squeeze, upper, lower = 31 + side, 37 + side, 19 + side, 21 + side
        assert fear[inner - 1] > 0 and fear[squeeze - 1] > 0 and surprise[squeeze - 1] <= 0
        assert surprise[upper - 1] < fear[upper - 1] < 0            # lids raised, less than surprise
        assert fear[lower - 1] > 0 > surprise[lower - 1]            # tensed up / let down
    for stretch in (53, 54, 6, 7):
        assert fear[stretch - 1] > 0 >= surprise[stretch - 1]
    assert 0 < fear[3 - 1] < surprise[3 - 1]

def test_joy_and_fear_on_the_levelled_risorius(mapping):
    # the risorius is levelled on the fitted head (fit.level_muscles, on): the stretch is AU20, not a
    # second smile, so joy (6+12) borrows no stretch and fear's corners no longer cancel a lift with
    # a hard pull-down (-600 MNS read as disgust's AU15 on MakeHuman); fear lowers the middle brow a
    # little (AU4) under the raised inner brow (AU1; docs/notes/ris23.md)
    joy, fear = mapping.expressions["joy"], mapping.expressions["fear"]
    for stretch in (53, 54, 6, 7):
        assert joy[stretch - 1] == 0
    for corner in (59, 60, 12, 13):
        assert -300 <= fear[corner - 1] <= -150
    for side in (0, 1):
        assert fear[31 + side - 1] > 0 > fear[33 + side - 1] > -fear[31 + side - 1]


def test_surprise_and_fear_widen_the_eyes_surprise_most(mapping):
    # AU5 (upper lid raiser) shows the sclera above the iris: a real lid rises 2-4 mm, 0.2-0.4 of a
    # 10 mm opening. Surprise (5B, the lower lids let down) opens each eye by 0.35 openings or more;
    # fear (5 with the lower lids tensed up) opens it too, by less. The lids play the FAP as asked up
    # to UPPER_OPEN of their fade (animation.eyelids). Surprise's lids once opened 1.30x (a person saw
    # no change on ICT) and fear's closed to 0.90x (narrower than neutral; docs/notes/read17.md)
    from faceforge.animation.eyelids import UPPER_OPEN

    limit = UPPER_OPEN * 0.5 * 1024        # IRISD at the default animate.eyelid_reach (0.5)
    fear, surprise = mapping.expressions["fear"], mapping.expressions["surprise"]
    for upper, lower in ((19, 21), (20, 22)):
        widen = {name: -row[upper - 1] - row[lower - 1] for name, row in (("fear", fear), ("surprise", surprise))}
        assert -surprise[upper - 1] >= 0.3 * 1024 and -surprise[upper - 1] <= limit
        assert widen["surprise"] >= 0.35 * 1024
        assert 0.1 * 1024 <= widen["fear"] < widen["surprise"]


def test_every_preset_fap_drives_something(mapping):
    # a preset's FAP that no entry maps would be dropped without a word; the lids (19-22) are
    # played over the skin by animation.eyelids
    mapped = set(mapping.mapped_faps().tolist()) | {19, 20, 21, 22}
    for table in (mapping.expressions, mapping.visemes):
        for name, row in table.items():
            used = {int(k) + 1 for k in np.flatnonzero(row)}
            assert used <= mapped, (name, sorted(used - mapped))
            assert used, name


def test_viseme_shapes_are_symmetric_and_twins_agree(mapping):
    # the mouth shapes of speech are left-right symmetric, and give an outer-lip FAP and its
    # inner-lip twin the same value (the mapping drives a twin pair by their mean)
    pairs = [(53, 54), (6, 7), (59, 60), (12, 13), (55, 56), (8, 9), (57, 58), (10, 11)]
    twins = [(e.faps[0], e.faps[1]) for e in mapping.entries if len(e.faps) == 2]
    for name, row in mapping.visemes.items():
        for a, b in pairs:
            assert row[a - 1] == row[b - 1], (name, a, b)
        for outer, inner in twins:
            assert row[outer - 1] == row[inner - 1], (name, outer, inner)


def test_rest_is_zero(mapping):
    c, jaw = fap_controls(mapping, np.zeros((3, N_FAPS)), mapping.muscles, FAPU, LEVERS)
    assert not c.any() and not jaw.any()


def test_contractions_clipped_and_jaw_limited(mapping):
    f = np.full((1, N_FAPS), 1e6)
    c, jaw = fap_controls(mapping, f, mapping.muscles, FAPU, LEVERS)
    assert c.max() == mapping.max_contraction and c.min() >= 0.0
    assert jaw[0, 0] == pytest.approx(mapping.jaw_limits["pitch"][1])
    assert jaw[0, 2] == pytest.approx(mapping.jaw_limits["protrusion"][1] * LEVERS.pitch)
    c, jaw = fap_controls(mapping, -f, mapping.muscles, FAPU, LEVERS)
    # the lower lip lowered 1e6 MNS opens the jaw (jaw_assisted) as far as it goes
    assert c.min() >= 0.0 and jaw[0, 0] == pytest.approx(mapping.jaw_limits["pitch"][1])
    plain = mapping
    for k, e in enumerate(mapping.entries):
        plain = with_entry(plain, k, muscle_reach=None)
    _, jaw = fap_controls(plain, -f, mapping.muscles, FAPU, LEVERS)
    assert jaw[0, 0] == pytest.approx(mapping.jaw_limits["pitch"][0])


def test_open_jaw_pitch_is_the_chin_arc(mapping):
    # 100 MNS units at a lever of 0.9: the chin travels 100 * MNS along the arc
    _, jaw = fap_controls(mapping, frames(f3=100), mapping.muscles, FAPU, LEVERS)
    assert jaw[0, 0] == pytest.approx(np.arctan2(100 * FAPU["MNS"], LEVERS.pitch))


def test_antagonists_by_sign(mapping):
    names = mapping.muscles
    up, _ = fap_controls(mapping, frames(f59=100, f12=100), names, FAPU, LEVERS)
    down, _ = fap_controls(mapping, frames(f59=-100, f12=-100), names, FAPU, LEVERS)
    zl, dl = names.index("zygomaticus_major_L"), names.index("depressor_anguli_L")
    assert up[0, zl] > 0 and up[0, dl] == 0
    assert down[0, dl] > 0 and down[0, zl] == 0


def test_inner_outer_twins_are_not_counted_twice(mapping):
    both, _ = fap_controls(mapping, frames(f53=100, f6=100), mapping.muscles, FAPU, LEVERS)
    # a file with only the outer FAP gets the inner one copied by the reader: same frames
    assert np.allclose(entry_drive(mapping, frames(f53=100, f6=100)).max(), 100.0)
    assert both.max() < 1.0


def test_left_right_mirror(mapping):
    names = list(mapping.muscles)
    left, _ = fap_controls(mapping, frames(f53=80, f6=80, f59=50, f12=50, f31=70, f41=40),
                           names, FAPU, LEVERS)
    right, _ = fap_controls(mapping, frames(f54=80, f7=80, f60=50, f13=50, f32=70, f42=40),
                            names, FAPU, LEVERS)
    swap = [names.index(n[:-1] + ("R" if n.endswith("L") else "L")) if n[-2:] in ("_L", "_R")
            else i for i, n in enumerate(names)]
    assert np.allclose(left[0, swap], right[0])


def test_jaw_coupling_removes_only_what_the_jaw_carries(mapping):
    # open_jaw alone must not contract the lip muscles (the lips part with the jaw)
    c, _ = fap_controls(mapping, frames(f3=300), mapping.muscles, FAPU, LEVERS)
    assert not c.any()
    e = mapping.entry_of(52)
    ratio = e.coupling[3]
    d = entry_drive(mapping, frames(f3=300, f52=-370, f5=-370))[0, mapping.entries.index(e)]
    assert d == pytest.approx(-(370 - abs(ratio) * 300))
    # a request smaller than what the jaw carries needs no depressor at all
    d = entry_drive(mapping, frames(f3=300, f52=-50, f5=-50))[0, mapping.entries.index(e)]
    assert d == 0.0


def test_lower_lip_past_its_muscles_opens_the_jaw_to_the_larger_need(mapping):
    # MPEG-4 lower-lip FAPs are absolute: alone past the muscles' reach the jaw opens for them
    e = mapping.entry_of(52)
    ratio, reach = e.coupling[3], e.muscle_reach
    j = mapping.entries.index(mapping.entry_of(3))
    k = mapping.entries.index(e)
    d = entry_drive(mapping, frames(f52=-870, f5=-870))[0]
    need = (870 - reach) / abs(ratio)
    assert d[j] == pytest.approx(need)                    # the jaw opens for the lip
    assert d[k] == pytest.approx(-reach)                  # the depressors give the rest
    # a file that opens the jaw further itself: the jaw takes the larger, not the sum
    d = entry_drive(mapping, frames(f3=need + 100, f52=-870, f5=-870))[0]
    assert d[j] == pytest.approx(need + 100)
    d = entry_drive(mapping, frames(f3=need - 100, f52=-870, f5=-870))[0]
    assert d[j] == pytest.approx(need)
    # within the muscles' reach, raised, or no reach: the jaw stays where the file puts it
    assert entry_drive(mapping, frames(f52=-reach, f5=-reach))[0, j] == 0.0
    assert entry_drive(mapping, frames(f52=300, f5=300))[0, j] == 0.0
    plain = with_entry(mapping, k, muscle_reach=None)
    assert entry_drive(plain, frames(f52=-870, f5=-870))[0, j] == 0.0


def test_expression_faps_scale_with_intensity(mapping):
    fap2 = np.array([[EXPRESSION_CODES["joy"], 63, 0, 0, 0, 0],
                     [EXPRESSION_CODES["joy"], 31.5, 0, 0, 0, 0],
                     [EXPRESSION_CODES["joy"], 63, EXPRESSION_CODES["surprise"], 63, 0, 0],
                     [0, 63, 0, 0, 0, 0]])
    low = expression_faps(mapping, fap2)
    assert np.allclose(low[0], mapping.expressions["joy"])
    assert np.allclose(low[1], 0.5 * low[0])
    assert np.allclose(low[2], mapping.expressions["joy"] + mapping.expressions["surprise"])
    assert not low[3].any()


def test_viseme_weights_follow_the_mpeg4_blend():
    a, u, pbm = VISEME_CODES["a"], VISEME_CODES["u"], VISEME_CODES["p_b_m"]
    fap1 = np.array([[a, 0, 63, 0],       # select1 alone needs blend 63
                     [a, 0, 0, 0],        # blend 0: all select2, here none
                     [a, u, 21, 0],       # a third a, two thirds u
                     [pbm, pbm, 40, 0],   # one viseme in both slots: both weights
                     [0, 15, 63, 0],      # none, and a code past the table
                     [a, u, 90, 1]])      # blend clipped to 63
    w = viseme_weights(fap1)
    assert w.shape == (6, 14)
    assert w[0, a - 1] == 1.0 and w[0].sum() == 1.0
    assert not w[1].any() and not w[4].any()
    assert w[2, a - 1] == pytest.approx(1 / 3) and w[2, u - 1] == pytest.approx(2 / 3)
    assert w[3, pbm - 1] == pytest.approx(1.0) and w[3].sum() == pytest.approx(1.0)
    assert w[5, a - 1] == 1.0 and w[5, u - 1] == 0.0


def test_viseme_faps_mix_the_shapes_and_name_the_missing_ones(mapping):
    a, o = VISEME_CODES["a"], VISEME_CODES["o"]
    fap1 = np.array([[a, o, 63, 0], [a, o, 31.5, 0], [0, 0, 0, 0]])
    low, missing = viseme_faps(mapping, fap1)
    assert missing == []
    assert np.array_equal(low[0], mapping.visemes["a"])
    assert np.allclose(low[1], 0.5 * (mapping.visemes["a"] + mapping.visemes["o"]))
    assert not low[2].any()
    # a mapping without the table plays nothing and says which visemes it lacks
    bare = mapping_from_dict({k: v for k, v in mapping_to_dict(mapping).items() if k != "visemes"})
    low, missing = viseme_faps(bare, fap1)
    assert not low.any() and missing == ["a", "o"]


def test_response_curve_passes_through_knots_and_origin():
    knots = np.array([[-100.0, -150.0], [50.0, 40.0], [100.0, 120.0]])
    v = np.array([-100.0, 0.0, 50.0, 100.0, 150.0, -200.0])
    out = response_curve(knots, v)
    assert np.allclose(out[:4], [-150.0, 0.0, 40.0, 120.0])
    assert out[4] == pytest.approx(120.0 + 50 * 80 / 50)   # last slope
    assert out[5] == pytest.approx(-300.0)                  # first slope through the origin
    assert np.allclose(response_curve(None, v), v)


def test_save_load_round_trip(mapping, tmp_path):
    knots = np.array([[-80.0, -95.0], [80.0, 130.5], [160.0, 300.25]])
    m = with_entry(mapping, 5, response=knots)
    save_fap_mapping(m, tmp_path / "m.yaml", header="calibrated\nfor a test")
    back = load_fap_mapping(tmp_path / "m.yaml")
    assert mapping_to_dict(back) == mapping_to_dict(m)
    f = np.random.default_rng(0).normal(0, 120, (20, N_FAPS))
    a = fap_controls(m, f, m.muscles, FAPU, LEVERS)
    b = fap_controls(back, f, m.muscles, FAPU, LEVERS)
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])


@pytest.mark.parametrize("edit, needle", [
    (lambda d: d["entries"][0].update(fap=2), "not a low-level FAP"),
    (lambda d: d["entries"][3].update(fapu="FOO"), "fapu must be one of"),
    (lambda d: d["entries"][3]["positive"].update(orbicularis_oris=-1), "gain must be >= 0"),
    (lambda d: d["entries"].append(dict(d["entries"][0])), "appears in two entries"),
    (lambda d: d["entries"][3].update(response=[[10, 5], [20, 1], [30, 8]]), "monotone"),
    (lambda d: d["jaw_limits"].update(pitch=[0.1, 0.4]), "lo <= 0 <= hi"),
    (lambda d: d["entries"][3].update(bogus=1), "unknown keys"),
    (lambda d: d["visemes"].update(schwa={"faps": {3: 50}}), "visemes.schwa: unknown viseme"),
    (lambda d: d["visemes"]["a"]["faps"].update({2: 10}), "not a low-level FAP"),
    (lambda d: d["expressions"].update(contempt={"faps": {3: 50}}), "unknown expression"),
    (lambda d: d.update(visemes=[1, 2]), "visemes: expected a mapping"),
])
def test_bad_mapping_errors_name_the_file(mapping, edit, needle):
    d = mapping_to_dict(mapping)
    edit(d)
    with pytest.raises(TemplateError) as err:
        mapping_from_dict(d, source="bad.yaml")
    assert needle in str(err.value) and str(err.value).startswith("bad.yaml: ")


def test_unknown_muscle_is_a_template_error(mapping):
    with pytest.raises(FaceforgeError, match="does not have"):
        mapping.check_muscles(["zygomaticus_major_L"])


def test_invalid_yaml_names_line(tmp_path):
    p = tmp_path / "m.yaml"
    p.write_text("entries:\n  - {fap: 3\n")
    with pytest.raises(TemplateError, match=r"m\.yaml:\d+: invalid YAML"):
        load_fap_mapping(p)


def test_a_muscle_shared_by_several_faps_takes_the_largest_request(mapping):
    names = mapping.muscles
    oo = names.index("orbicularis_oris")
    one, _ = fap_controls(mapping, frames(f51=100, f4=100), names, FAPU, LEVERS)
    three, _ = fap_controls(mapping, frames(f51=100, f4=100, f55=100, f8=100, f56=100, f9=100),
                            names, FAPU, LEVERS)
    assert one[0, oo] > 0 and three[0, oo] == pytest.approx(one[0, oo])
    bigger, _ = fap_controls(mapping, frames(f51=100, f4=100, f55=150, f8=150), names, FAPU, LEVERS)
    assert bigger[0, oo] > one[0, oo]


def test_max_contraction_is_validated(mapping):
    d = mapping_to_dict(mapping)
    d["max_contraction"] = 1.5
    with pytest.raises(TemplateError, match="max_contraction"):
        mapping_from_dict(d, source="m.yaml")
