"""Scenario tests: the animate and calibrate stages on a synthetic fitted + bound head.

The head (tests/animation/synthetic.py) goes through the real bind stage; the stages then run
the real layered system (kinematic skull, one PBD muscle, the PBD skin) frame by frame.
"""

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from tests.animation import synthetic as S

ROOT = Path(__file__).resolve().parents[2]
JOY = ROOT / "samples" / "fap" / "joy.fap"
SETS = ("animate.calibrate.refine=3",)


@pytest.fixture(scope="module")
def workdir(tmp_path_factory):
    """A workdir with fit/ and bind/ of the synthetic head and the synthetic mapping."""
    from faceforge.io.config import load_config
    from faceforge.pipeline import StageContext
    from faceforge.pipeline.stages.bind import run as run_bind

    root = tmp_path_factory.mktemp("animate_head")
    S.write_fit(root / "fit")
    (root / "bind").mkdir()
    run_bind(StageContext(name="bind", config=load_config(), params={}, out_dir=root / "bind",
                          workdir=root, deps=("fit",)))
    (root / "mapping.yaml").write_text(yaml.safe_dump(S.MAPPING))
    return root


@pytest.fixture(scope="module")
def patched():
    """The synthetic head has no template muscles: build its muscles with the synthetic builder.

    Module-scoped: the patch must not leak into later test modules (the sample-head tests
    rebuild the real muscles)."""
    import faceforge.animation.rig as rig
    import faceforge.pipeline.stages.animate as stage

    mp = pytest.MonkeyPatch()
    mp.setattr(rig, "muscle_system", S.muscle_system)
    yield stage
    mp.undo()


class ConfigSpy:
    """A Config that records every key a stage reads."""

    def __init__(self, config):
        self._config, self.read = config, []

    def get(self, key, *args, **kwargs):
        self.read.append(key)
        return self._config.get(key, *args, **kwargs)

    def __getattr__(self, name):
        return getattr(self._config, name)


def run_stage(stage_name, workdir, params, sets=SETS, reads=None, logged=None):
    """Run one stage in ``workdir``; ``reads`` (a list): record into it every config key read;
    ``logged`` (a list): the stage's log lines."""
    from faceforge.io.config import load_config
    from faceforge.pipeline import StageContext, get_stage

    out = workdir / f"{stage_name}.out"
    if out.exists():
        import shutil
        shutil.rmtree(out)
    out.mkdir()
    config = load_config(None, sets)
    if reads is not None:
        config = ConfigSpy(config)
        config.read = reads
    ctx = StageContext(name=stage_name, config=config, params=params, out_dir=out, workdir=workdir,
                       deps=("fit", "bind"), **({} if logged is None else {"logger": logged.append}))
    get_stage(stage_name).run(ctx)
    return out


def undeclared_reads(stage_name, reads) -> set:
    """The keys in ``reads`` that lie in none of the stage's ``config_keys`` subtrees."""
    from faceforge.pipeline import get_stage

    declared = get_stage(stage_name).config_keys
    return {k for k in reads if not any(k == p or k.startswith(p + ".") for p in declared)}


CALIBRATE_READ = []


@pytest.fixture(scope="module")
def calibrated(workdir, patched):
    return run_stage("calibrate", workdir, {}, sets=(*SETS, f"animate.fap_mapping={workdir / 'mapping.yaml'}"),
                     reads=CALIBRATE_READ)


def test_calibrate_reads_only_the_config_keys_it_declares(calibrated):
    """The calibrate stage's cache key holds its ``config_keys``: every key it reads must lie in
    one of them (else a change would leave a stale calibration), and the playback-only keys
    (head rotation, previews) stay out (a change to them costs no recalibration)."""
    from faceforge.pipeline import get_stage

    assert {"animate.calibrate.refine", "solver"} <= set(CALIBRATE_READ)
    assert not undeclared_reads("calibrate", CALIBRATE_READ)
    assert not ({"animate", "animate.head_rotation", "animate.neck_fade", "animate.preview_frames"}
                & set(get_stage("calibrate").config_keys))


ANIMATE_READ = []


@pytest.fixture(scope="module")
def joy(workdir, patched):
    return run_stage("animate", workdir, {"fap": str(JOY), "animate_mapping": str(workdir / "mapping.yaml")},
                     reads=ANIMATE_READ)


def test_animate_reads_only_the_config_keys_it_declares(joy):
    """As for calibrate below: every key the animate stage reads lies in its ``config_keys``.
    (The synthetic head builds its own muscles; a real head's also reads ``template.*``, the
    fit stage's keys, upstream of this one.)"""
    assert {"animate.head_rotation", "solver"} <= set(ANIMATE_READ)
    assert not undeclared_reads("animate", ANIMATE_READ)


def test_joy_plays_clean_in_user_vertex_order(joy):
    from faceforge.io.stagefiles import load_npz
    from faceforge.mpeg4 import read_fap

    d = load_npz(joy / "animation.npz")
    report = json.loads((joy / "report.json").read_text())
    v, _ = S.skin_mesh()
    track = read_fap(JOY)
    assert d["frames"].shape == (track.n_frames, len(v), 3)       # the lip cut's copies dropped
    assert float(d["fps"]) == track.fps
    checks = report["checks"]
    assert checks["non_finite"] == 0 and checks["inverted_triangles"] == 0
    assert checks["skin_inside_skull"] == 0
    assert report["max_contraction"] > 0.1 and report["max_jaw"][0] > 0.0
    # the Xface joy file carries eyeball FAPs that this head cannot play; its eyelid FAPs move
    # the lids and its head FAPs turn the whole head
    unmapped = set(report["unmapped_faps"])
    assert 23 in unmapped and not {19, 20, 21, 22, 48, 49, 50} & unmapped and report["eyes_with_lids"] == 2
    assert 0.5 < max(report["max_head_rotation_deg"]) < 5.0
    from faceforge.pbd.threads import threads_used
    assert report["threads"] == threads_used(2)   # solver.partitions: 2; its muscle layers are cut
    # frame 0 of joy.fap is nearly neutral; the peak moves the skin
    assert np.abs(d["frames"][0] - v).max() < 0.02
    assert np.abs(d["frames"] - v).max() > 0.02


def test_exports_round_trip_with_the_input_vertex_order(joy, tmp_path):
    from faceforge.io.export import export_animation, read_glb, read_mdd, read_obj_sequence, read_pc2
    from faceforge.io.stagefiles import load_npz

    d = load_npz(joy / "animation.npz")
    frames, fps = d["frames"][:12], float(d["fps"])
    _, faces = S.skin_mesh()
    pc2 = read_pc2(export_animation(tmp_path / "a.pc2", frames, faces, fps))[0]
    mdd = read_mdd(export_animation(tmp_path / "a.mdd", frames, faces, fps))[0]
    assert np.array_equal(pc2, frames) and np.array_equal(mdd, frames)
    obj = read_obj_sequence(export_animation(tmp_path / "seq", frames, faces, fps))
    assert np.allclose(obj[0], frames, atol=1e-5)
    glb = read_glb(export_animation(tmp_path / "a.glb", frames, faces, fps))
    assert np.allclose(glb[0], frames, atol=1e-5)


def test_neutral_track_is_a_fixed_point(workdir, patched, tmp_path):
    from faceforge.io.stagefiles import load_npz
    from faceforge.mpeg4 import FapTrack, write_fap

    n = 6
    track = FapTrack.from_given(25.0, np.ones((n, 68), bool), np.zeros((n, 68)))
    write_fap(tmp_path / "zero.fap", track)
    out = run_stage("animate", workdir, {"fap": str(tmp_path / "zero.fap"),
                                         "animate_mapping": str(workdir / "mapping.yaml")})
    frames = load_npz(out / "animation.npz")["frames"]
    v, _ = S.skin_mesh()
    assert np.abs(frames - v.astype(np.float32)).max() < 1e-5


@pytest.mark.parametrize("turn", [True, False])
def test_head_faps_turn_the_head_as_a_whole(workdir, patched, tmp_path, turn):
    """A neutral face under FAPs 48-50 alone: every frame is the rest skin turned about the
    midpoint of the jaw's condyles (the simulation's rest state is a fixed point), rigidly down
    to the skull's lowest point, the skin below fading out of the turn (over a tenth of the
    skull's height: the synthetic skin reaches 0.3 below its skull); with ``animate.head_rotation`` off the FAPs are reported unmapped and the skin stays
    at rest."""
    from faceforge.animation.head_motion import head_angles, head_rotations
    from faceforge.io.stagefiles import load_npz
    from faceforge.mpeg4 import FapTrack, write_fap

    n = 5
    values = np.zeros((n, 68))
    values[:, 47:50] = np.linspace(0.0, 1.0, n)[:, None] * [4000.0, -6000.0, 3000.0]
    write_fap(tmp_path / "head.fap", FapTrack.from_given(25.0, np.ones((n, 68), bool), values))
    out = run_stage("animate", workdir, {"fap": str(tmp_path / "head.fap"),
                                         "animate_mapping": str(workdir / "mapping.yaml")},
                    sets=(*SETS, f"animate.head_rotation={str(turn).lower()}", "animate.neck_fade=0.1"))
    frames = load_npz(out / "animation.npz")["frames"]
    report = json.loads((out / "report.json").read_text())
    v, _ = S.skin_mesh()
    if not turn:
        assert report["unmapped_faps"] == [48, 49, 50]
        assert np.abs(frames - v).max() < 1e-5
        return
    fit = load_npz(workdir / "fit" / "fit.npz")
    pivot = fit["jaw_yaw_point"]
    bone_y = np.concatenate([fit["cranium_vertices"][:, 1], fit["mandible_vertices"][:, 1]])
    low, span = bone_y.min(), 0.1 * np.ptp(bone_y)
    head, neck_base = v[:, 1] >= low, v[:, 1] <= low - span
    assert head.sum() > 100 and neck_base.sum() > 100
    rigid = np.einsum("fij,nj->fni", head_rotations(head_angles(values)), v - pivot) + pivot
    assert report["unmapped_faps"] == []
    assert np.degrees(0.06) == pytest.approx(max(report["max_head_rotation_deg"]))
    assert np.abs(frames[:, head] - rigid[:, head]).max() < 1e-5
    assert np.abs(frames[:, neck_base] - v[neck_base]).max() < 1e-5
    neck = ~head & ~neck_base                           # in between: part of the turn, no more
    moved = np.linalg.norm(frames[-1, neck] - v[neck], axis=1)
    assert np.all(moved <= np.linalg.norm(rigid[-1, neck] - v[neck], axis=1) + 1e-5)
    assert np.abs(frames[-1] - v).max() > 0.01          # it did turn (head ~2 units across)
    assert report["checks"]["skin_inside_skull"] == 0    # checked in the skull's own frame


@pytest.mark.parametrize("lids", [True, False])
def test_eyelid_faps_close_the_lids_of_the_still_face(workdir, patched, tmp_path, lids):
    """FAPs 19-22 alone on a neutral face: the rest skin (the simulation's fixed point) with the
    lids moved over it (animation.eyelids), by exactly the requested IRISD at the lid FDPs; skin
    away from the eyes stays where it is, and nothing turns over. With ``animate.eyelids`` off
    the FAPs are reported unmapped and the skin stays at rest."""
    from faceforge.animation.eyelids import MIN_OPENING
    from faceforge.io.stagefiles import load_npz
    from faceforge.mpeg4 import FapTrack, fapu_from_landmarks, write_fap

    n = 3
    values = np.zeros((n, 68))
    values[:, 18:22] = np.array([[0, 0, 0, 0], [512, 300, 100, 0], [1024, 1024, 0, 200]])
    write_fap(tmp_path / "blink.fap", FapTrack.from_given(25.0, np.ones((n, 68), bool), values))
    out = run_stage("animate", workdir, {"fap": str(tmp_path / "blink.fap"),
                                         "animate_mapping": str(workdir / "mapping.yaml")},
                    sets=(*SETS, f"animate.eyelids={str(lids).lower()}"))
    frames = load_npz(out / "animation.npz")["frames"]
    report = json.loads((out / "report.json").read_text())
    v, f = S.skin_mesh()
    if not lids:
        assert report["unmapped_faps"] == [19, 20, 21, 22] and report["eyes_with_lids"] == 0
        assert np.abs(frames - v).max() < 1e-5
        return
    assert report["unmapped_faps"] == [] and report["eyes_with_lids"] == 2
    assert report["checks"]["inverted_triangles"] == 0
    lm = S.landmarks(v)
    irisd = fapu_from_landmarks(lm, "synthetic").unit("IRISD")
    fdp = {k: int(np.argmin(np.linalg.norm(v - p, axis=1))) for k, p in lm.items()}
    for k, (fap, sign) in {"3.1": (19, -1), "3.2": (20, -1), "3.3": (21, 1), "3.4": (22, 1)}.items():
        assert frames[1, fdp[k], 1] - v[fdp[k], 1] == pytest.approx(sign * values[1, fap - 1] * irisd, abs=2e-6)
    for up, low in (("3.1", "3.3"), ("3.2", "3.4")):   # a full blink: the lids (nearly) meet
        gap = v[fdp[up], 1] - v[fdp[low], 1]
        assert MIN_OPENING * gap / 2 < frames[2, fdp[up], 1] - frames[2, fdp[low], 1] < 2 * MIN_OPENING * gap
    far = np.linalg.norm(v - 0.5 * (lm["3.1"] + lm["3.2"]), axis=1) > 0.8
    assert far.sum() > len(v) // 2
    assert np.abs(frames[:, far] - v[far]).max() < 1e-5
    assert np.abs(frames[1] - v).max() > 0.01


def test_a_mapping_without_visemes_says_fap_1_is_not_played(workdir, patched, tmp_path):
    """Visemes (FAP 1) are read but the mapping has no viseme table: the report lists FAP 1 as
    unmapped (rather than dropping it silently) and the face stays at rest."""
    from faceforge.io.stagefiles import load_npz
    from faceforge.mpeg4 import FapTrack, write_fap

    n = 3
    mask = np.zeros((n, 68), bool)
    mask[:, 0] = True
    track = FapTrack.from_given(25.0, mask, np.zeros((n, 68)), viseme=np.tile([3.0, 5.0, 40.0, 0.0], (n, 1)))
    write_fap(tmp_path / "visemes.fap", track)
    out = run_stage("animate", workdir, {"fap": str(tmp_path / "visemes.fap"),
                                         "animate_mapping": str(workdir / "mapping.yaml")})
    assert json.loads((out / "report.json").read_text())["unmapped_faps"] == [1]
    v, _ = S.skin_mesh()
    assert np.abs(load_npz(out / "animation.npz")["frames"] - v).max() < 1e-5


def test_visemes_play_as_their_low_level_faps(workdir, patched, tmp_path):
    """A FAP 1 track plays the mapping's viseme shapes: bit for bit the frames of the same mouth
    shapes given as low-level FAPs (the two visemes of each frame mixed by viseme_blend / 63),
    and the report names the visemes played."""
    import yaml

    from faceforge.animation.fap_mapping import mapping_from_dict, viseme_faps
    from faceforge.io.stagefiles import load_npz
    from faceforge.mpeg4 import FapTrack, viseme_track, write_fap

    mapping = {**S.MAPPING, "visemes": {"a": {"id": 10, "faps": {3: 250}},
                                        "i": {"id": 12, "faps": {3: 60, 59: 120, 12: 120}}}}
    (tmp_path / "mapping.yaml").write_text(yaml.safe_dump(mapping))
    said = viseme_track(["a", "i", "a"], fps=25, each=0.16, blend=0.08, ramp=0.08)
    write_fap(tmp_path / "said.fap", said)
    low, missing = viseme_faps(mapping_from_dict(mapping), said.viseme)
    assert missing == [] and low[:, 2].max() == 250.0
    given = np.zeros_like(low, dtype=bool)
    given[:, np.flatnonzero(np.abs(low).max(axis=0))] = True    # every frame (absent FAPs hold)
    write_fap(tmp_path / "low.fap", FapTrack.from_given(25.0, given, low))
    runs = {}
    for name in ("said", "low"):
        out = run_stage("animate", workdir, {"fap": str(tmp_path / f"{name}.fap"),
                                             "animate_mapping": str(tmp_path / "mapping.yaml")})
        runs[name] = (load_npz(out / "animation.npz"), json.loads((out / "report.json").read_text()))
    (a, rep_a), (b, rep_b) = runs["said"], runs["low"]
    assert rep_a["visemes"] == ["a", "i"] and rep_b["visemes"] == []
    assert rep_a["unmapped_faps"] == [] and rep_a["checks"]["ok"]
    assert np.array_equal(a["frames"], b["frames"]) and np.array_equal(a["jaw"], b["jaw"])
    assert a["jaw"][:, 0].max() > 0.0 and a["contractions"][:, 0].max() > 0.0   # the jaw opens, the smile pulls


def test_the_warm_up_leaves_the_frames_of_a_cold_play(workdir, patched, tmp_path):
    """animate plays the first frame once before the timed playback (numba compiles there, not
    in the ms/frame), then resets the rig: its frames are bit for bit those of a fresh head
    played without the warm-up."""
    from faceforge.animation.controls import track_controls
    from faceforge.animation.fap_mapping import load_fap_mapping
    from faceforge.animation.playback import play
    from faceforge.animation.rig import BoundHead
    from faceforge.io.config import load_config
    from faceforge.io.stagefiles import load_npz
    from faceforge.mpeg4 import FapTrack, read_fap, write_fap

    n = 12
    values = np.zeros((n, 68))
    values[:, 2] = np.linspace(0.0, 200.0, n)                  # open_jaw
    values[:, [58, 11]] = np.linspace(0.0, 150.0, n)[:, None]  # raise_l_cornerlip, outer and inner
    given = np.zeros((n, 68), dtype=bool)
    given[:, [2, 58, 11]] = True
    write_fap(tmp_path / "smile.fap", FapTrack.from_given(25.0, given, values))
    out = run_stage("animate", workdir, {"fap": str(tmp_path / "smile.fap"),
                                         "animate_mapping": str(workdir / "mapping.yaml")})
    head = BoundHead(workdir / "fit", workdir / "bind", load_config(None, SETS))
    c, jaw, _, _ = track_controls(read_fap(tmp_path / "smile.fap"), load_fap_mapping(workdir / "mapping.yaml"), head)
    cold = play(head.rig, c, jaw, 25.0)
    lids = head.eyelids(load_config(None, SETS))
    if lids is not None:   # animate.eyelid_jaw_hold: the opening jaw's frames hold the upper lids
        cold = lids.apply(cold, np.nan_to_num(read_fap(tmp_path / "smile.fap").values), jaw)
    cold = head.to_user(cold).astype(np.float32)
    assert np.array_equal(load_npz(out / "animation.npz")["frames"], cold)
    assert c[:, 0].max() > 0.0 and jaw[:, 0].max() > 0.0


def test_the_warm_up_says_when_it_compiled_and_resets_the_rig():
    import time

    from faceforge.animation.playback import Rig
    from faceforge.animation.playback import warm_up

    calls = []
    for delay, said in ((0.0, False), (1.05, True)):
        calls.clear()
        logged = []
        rig = Rig(skull=lambda jaw, d=delay: time.sleep(d), muscles=lambda c, b, dt: calls.append("step"),
                  skin=lambda b, m, dt: np.zeros((3, 3)), rest=np.zeros((3, 3)),
                  reset=lambda: calls.append("reset"))
        seconds = warm_up(rig, np.zeros((5, 1)), np.zeros((5, 3)), 25.0, logged.append)
        assert calls == ["reset", "step", "reset"]              # one frame, at rest before and after
        assert (seconds > 1.0) == said == any("compiled the simulation kernels" in m for m in logged)
    calls.clear()
    assert warm_up(rig, np.zeros((0, 1)), np.zeros((0, 3)), 25.0, logged.append) == 0.0
    assert calls == ["reset"]                                   # an empty track: nothing played, at rest


def test_calibration_report_meets_the_acceptance(calibrated):
    report = json.loads((calibrated / "report.json").read_text())
    s = report["summary"]
    assert s["all"]["count"] >= 6
    assert s["all"]["median_relative_error"] <= 0.10
    assert s["all"]["median_relative_error"] < s["all_uncalibrated"]["median_relative_error"]
    # open_jaw parts the lips by the requested amount within 15 %
    assert report["open_jaw_lip_separation"]["relative_error"] <= 0.15
    # the calibrated mapping is a valid mapping with response curves and a measured coupling
    from faceforge.animation.fap_mapping import load_fap_mapping

    m = load_fap_mapping(calibrated / "fap_mapping.yaml")
    assert m.entry_of(3).response is not None and m.entry_of(59).response is not None
    assert m.entry_of(52).coupling[3] < 0.0           # open_jaw lowers the lower lip
    assert all("relative_error" in row for row in report["rows"])
    # the text report gives the JSON's median as a percentage
    assert (f"median relative error (lip, jaw, cheek, eyebrow): "
            f"{100 * s['all']['median_relative_error']:.1f}%;") in (calibrated / "report.txt").read_text()


def test_expression_preset_through_fap2(workdir, patched, tmp_path):
    from faceforge.io.stagefiles import load_npz
    from faceforge.mpeg4 import expression_track, fapu_from_landmarks, write_fap

    write_fap(tmp_path / "joy_preset.fap", expression_track("joy", intensity=0.8, fps=25, seconds=0.6, ramp=0.2))
    out = run_stage("animate", workdir, {"fap": str(tmp_path / "joy_preset.fap"),
                                         "animate_mapping": str(workdir / "mapping.yaml")})
    d = load_npz(out / "animation.npz")
    c = d["contractions"][:, 0]
    assert c[0] == 0.0 and c[-1] == 0.0                        # ramps in from and out to neutral
    assert c.max() == pytest.approx(0.8 * 150 * 0.003)         # joy's corner FAPs x intensity x gain
    assert json.loads((out / "report.json").read_text())["unmapped_faps"] == []
    # joy's eyelid FAPs (upper lids 128 down, lower 64 up), scaled the same way, narrow the eyes:
    # MPEG-4 lid FAPs are displacements from neutral, so the lid FDPs end exactly that far from
    # rest, whatever the simulated skin did (eyelids.held_share); without lids they move less
    bare = run_stage("animate", workdir, {"fap": str(tmp_path / "joy_preset.fap"),
                                          "animate_mapping": str(workdir / "mapping.yaml")},
                     sets=(*SETS, "animate.eyelids=false"))
    moved = d["frames"].astype(np.float64)
    bare = load_npz(bare / "animation.npz")["frames"].astype(np.float64)
    v, _ = S.skin_mesh()
    lm = S.landmarks(v)
    irisd = fapu_from_landmarks(lm, "synthetic").unit("IRISD")
    hold = int(np.argmax(c))
    for fdp, move in {"3.1": -128, "3.2": -128, "3.3": 64, "3.4": 64}.items():
        i = int(np.argmin(np.linalg.norm(v - lm[fdp], axis=1)))
        assert moved[hold, i, 1] - v[i, 1] == pytest.approx(0.8 * move * irisd, rel=1e-4)
        assert abs(bare[hold, i, 1] - v[i, 1]) < abs(0.8 * move * irisd)


def test_playing_the_calibration_takes_the_presets_from_the_template(workdir, patched, calibrated, tmp_path):
    """The workdir's calibration carries a copy of the expression presets; played, the presets
    are those of the template (``animate.fap_mapping``), so an edited preset needs no
    recalibration: joy's upper lids at 300 in the template (128 in the calibrated copy) drop
    FDP 3.1 by 0.8 x 300 IRISD at intensity 0.8."""
    import shutil

    from faceforge.io.stagefiles import load_npz
    from faceforge.mpeg4 import expression_track, fapu_from_landmarks, write_fap

    (workdir / "calibrate").mkdir(exist_ok=True)
    shutil.copy(calibrated / "fap_mapping.yaml", workdir / "calibrate" / "fap_mapping.yaml")
    edited = yaml.safe_load((workdir / "mapping.yaml").read_text())
    edited["expressions"]["joy"]["faps"][19] = 300
    (tmp_path / "edited.yaml").write_text(yaml.safe_dump(edited))
    write_fap(tmp_path / "joy.fap", expression_track("joy", intensity=0.8, fps=25, seconds=0.6, ramp=0.2))
    played = {lids: load_npz(run_stage(
        "animate", workdir, {"fap": str(tmp_path / "joy.fap"),
                             "animate_mapping": str(workdir / "calibrate" / "fap_mapping.yaml")},
        sets=(*SETS, f"animate.fap_mapping={tmp_path / 'edited.yaml'}",
              f"animate.eyelids={str(lids).lower()}")) / "animation.npz") for lids in (True, False)}
    v, _ = S.skin_mesh()
    lm = S.landmarks(v)
    i = int(np.argmin(np.linalg.norm(v - lm["3.1"], axis=1)))
    hold = int(np.argmax(played[True]["contractions"][:, 0]))
    drop = played[True]["frames"][hold, i, 1].astype(float) - v[i, 1]        # lid FAPs: from neutral
    assert drop == pytest.approx(-0.8 * 300 * fapu_from_landmarks(lm, "synthetic").unit("IRISD"), rel=1e-4)


def test_a_diverging_simulation_is_a_one_line_stage_error_naming_the_track(workdir, patched, monkeypatch):
    import faceforge.animation.playback as anim
    from faceforge.exceptions import StageError

    def diverges(*args, **kwargs):
        raise FloatingPointError("frame 3: the simulation produced non-finite skin positions")

    monkeypatch.setattr(anim, "play", diverges)
    with pytest.raises(StageError, match=r"joy\.fap.*frame 3.*diverged") as err:
        run_stage("animate", workdir, {"fap": str(JOY), "animate_mapping": str(workdir / "mapping.yaml")})
    assert "\n" not in str(err.value)


@pytest.mark.parametrize("ran", [True, False])
def test_calibrate_command_says_wrote_only_when_the_stage_ran(tmp_path, ran):
    """An up-to-date `faceforge calibrate` prints the kept report, not "wrote"."""
    from types import SimpleNamespace

    from click.testing import CliRunner

    from faceforge.pipeline.stages.calibrate import calibrate_command

    (tmp_path / "report.txt").write_text("median relative error 0.05\n")
    lines = []
    app = SimpleNamespace(
        run_stage=lambda name, force: [SimpleNamespace(ran=ran, stage=SimpleNamespace(name=name))],
        workspace=SimpleNamespace(stage_dir=lambda name: tmp_path), log=lines.append)
    result = CliRunner().invoke(calibrate_command, [], obj=app)
    assert result.exit_code == 0, result.output
    assert lines[0].startswith("median relative error")
    assert lines[1].startswith("calibrate: wrote " if ran else "calibrate: kept ")


def test_editing_a_preset_leaves_the_calibration_up_to_date(tmp_path):
    """The calibrate stage digests its template without the presets: a preset edit keeps the
    key (no recalibration), an entry edit changes it."""
    from faceforge.pipeline import get_stage
    from faceforge.pipeline.runner import current_record

    mapping = yaml.safe_load(yaml.safe_dump(S.MAPPING))
    path = tmp_path / "m.yaml"

    def record():
        path.write_text(yaml.safe_dump(mapping))
        from faceforge.io.config import load_config

        config = load_config(None, (f"animate.fap_mapping={path}",))
        return current_record(get_stage("calibrate"), config, {}, {"fit": "f", "bind": "b"})[0]["inputs"]

    before = record()
    mapping["expressions"]["joy"]["faps"][19] = 400
    assert record() == before
    mapping["entries"][0]["fapu"] = "MW"
    assert record() != before


def test_expressions_sheet_settles_each_preset_and_checks_it(workdir, patched, tmp_path):
    """``faceforge expressions``: the neutral face and the six presets, settled one by one.
    The neutral pose is the rest skin (the simulation's fixed point); joy contracts the
    zygomaticus by its FAP x gain and opens the jaw; every pose passes the physical checks;
    the sheet has seven panels in two rows."""
    import matplotlib.image as mpimg

    from faceforge.io.stagefiles import load_npz
    from faceforge.mpeg4.expressions import EXPRESSIONS

    mapping = yaml.safe_load(yaml.safe_dump(S.MAPPING))
    for i, name in enumerate(EXPRESSIONS):
        if name != "joy":   # the synthetic head's muscle is the zygomaticus: jaw and lid presets
            mapping["expressions"][name] = {"id": i + 1, "faps": {3: 40.0 * i, 19: -50.0 * i}}
    (tmp_path / "six.yaml").write_text(yaml.safe_dump(mapping))
    out = run_stage("expressions", workdir, {"animate_mapping": str(tmp_path / "six.yaml")})
    d = load_npz(out / "expressions.npz")
    report = json.loads((out / "report.json").read_text())
    assert list(d["names"]) == ["neutral", *EXPRESSIONS]
    v, _ = S.skin_mesh()
    assert np.abs(d["poses"][0] - v).max() < 1e-5
    joy = list(d["names"]).index("joy")
    assert d["contractions"][joy, 0] == pytest.approx(150 * 0.003)
    assert d["jaw"][joy, 0] > 0.0 and np.abs(d["poses"][joy] - v).max() > 0.01
    assert all(e["checks"]["inverted_triangles"] == 0 and e["checks"]["skin_inside_skull"] == 0
               for e in report["expressions"].values()) and len(report["expressions"]) == 7
    # held until converged (issue 25 item 6): each pose says its frames and residual
    assert report["statics"]["unconverged"] == 0 and report["statics"]["residual_max"] <= 5e-5
    assert all(e["converged"] and e["frames"] > 10 for e in report["expressions"].values())
    img = mpimg.imread(out / "expressions.png")
    # two poses a row, each with its heat map beside it (four panels wide), four rows; a panel
    # of 3.2 in at 120 dpi: the face >= 300 px
    assert 0.7 * img.shape[0] < img.shape[1] < 1.1 * img.shape[0] and img.shape[1] >= 4 * 300


def test_expressions_needs_all_six_presets(workdir, patched):
    from faceforge.exceptions import StageError

    with pytest.raises(StageError, match="no preset for sadness"):
        run_stage("expressions", workdir, {"animate_mapping": str(workdir / "mapping.yaml")})


def test_visemes_sheet_settles_the_shapes_the_table_has(workdir, patched, tmp_path):
    """``faceforge visemes``: the neutral face and each viseme of the mapping's table, in the
    standard's order, settled as a static pose (the shapes through the same mapping as a FAP
    track); the visemes the table lacks are named and left out."""
    from faceforge.io.stagefiles import load_npz

    mapping = {**yaml.safe_load(yaml.safe_dump(S.MAPPING)),
               "visemes": {"i": {"faps": {3: 60, 59: 120, 12: 120}}, "a": {"faps": {3: 250}}}}
    (tmp_path / "two.yaml").write_text(yaml.safe_dump(mapping))
    logged = []
    out = run_stage("visemes", workdir, {"animate_mapping": str(tmp_path / "two.yaml")}, logged=logged)
    d = load_npz(out / "visemes.npz")
    report = json.loads((out / "report.json").read_text())
    assert list(d["names"]) == ["neutral", "a", "i"]            # code order: a is 10, i is 12
    v, _ = S.skin_mesh()
    assert np.abs(d["poses"][0] - v).max() < 1e-5
    assert d["contractions"][2, 0] == pytest.approx(120 * 0.003) and d["contractions"][1, 0] == 0.0
    assert d["jaw"][1, 0] > d["jaw"][2, 0] > 0.0                  # a opens the jaw more than i
    assert all(e["checks"]["ok"] for e in report["visemes"].values())
    assert (out / "visemes.png").stat().st_size > 0
    assert any("no shape for p_b_m, f_v, th" in line for line in logged), logged


def test_visemes_needs_a_table(workdir, patched):
    from faceforge.exceptions import StageError

    with pytest.raises(StageError, match="no visemes table"):
        run_stage("visemes", workdir, {"animate_mapping": str(workdir / "mapping.yaml")})


@pytest.mark.parametrize("back_per_down", [0.2, 0.33])
def test_the_chin_path_sets_the_glide_per_head(workdir, patched, back_per_down):
    """``animate.chin_path`` solves this head's glide: its chin (FDP 2.1, on the mandible) goes
    back that fraction of its drop at a 10 degree opening; 0 keeps ``animate.jaw_glide``."""
    from faceforge.anatomy.skull import apply_transform, jaw_transform
    from faceforge.animation.rig import BoundHead
    from faceforge.io.config import load_config

    fixed = BoundHead(workdir / "fit", workdir / "bind",
                      load_config(None, (*SETS, "animate.chin_path=0", "animate.jaw_glide=0.45")))
    assert fixed.jaw_glide == 0.45
    head = BoundHead(workdir / "fit", workdir / "bind", load_config(None, (*SETS, f"animate.chin_path={back_per_down}")))
    chin = np.asarray(head.landmarks["2.1"], dtype=float)
    d = apply_transform(jaw_transform(head.skull, np.radians(10.0), 0.0, 0.0), chin[None])[0] - chin
    assert -d[1] > 0 and np.isclose(-d[2] / -d[1], back_per_down, atol=1e-9)
