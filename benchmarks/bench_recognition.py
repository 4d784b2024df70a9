"""Do the six expression presets read as joy, sadness, anger, fear, disgust and surprise to a
face-reading model? (issue 25 item 4)

Usage::

    python benchmarks/bench_recognition.py WORKDIR [WORKDIR ...] [--out NAME] [--pictures DIR] [--units] [--eyes]

Each WORKDIR is fitted, bound and (as ``animate`` plays it) calibrated. For each head the
neutral face and the six presets of the template mapping (``expressions:``) at full intensity
are settled as ``faceforge expressions`` settles them (held until the skin stops moving, the
eyelids laid over), rendered smooth-shaded grey on black (:func:`faceforge.landmarks.
blendshapes.grey_render`: the landmark detector's z-buffer, vertex normals), 512 x 512 pixels
with the face's box (``viz.contact_sheet.face_region``: chin to above the brows) 369 pixels
high, from the front and turned 20 degrees (a slight three-quarter view, the subject's left
cheek towards the camera), and scored by MediaPipe's Face Landmarker blendshape head (52
ARKit names; :class:`faceforge.landmarks.blendshapes.BlendshapeScorer`, the model the
landmark detector ships).

**The rule.** Each expression is its FACS prototype (joy 6+12, sadness 1+4+15, anger
4+5+7+23, fear 1+2+4+5+20+26, disgust 9+15+16, surprise 1+2+5+26). An action unit's score is
the mean of its ARKit scores (AU1 browInnerUp, AU2 browOuterUp L/R, AU4 browDown L/R, AU5
eyeWide L/R, AU6 cheekSquint L/R, AU7 eyeSquint L/R, AU9 noseSneer L/R, AU12 mouthSmile L/R,
AU15 mouthFrown L/R, AU16 mouthLowerDown L/R, AU20 mouthStretch L/R, AU23 mouthPress L/R,
AU26 jawOpen). An expression's score on a render is the mean over its AUs of (the render's AU
score - the neutral render's AU score), same head, same view. A preset is **recognised** when
its own expression scores highest of the six.

``--eyes``: each eye drawn with an eyeball behind its lids (:func:`faceforge.landmarks.
blendshapes.eyeballs`: the sphere the kinematic lids slide over, ``animation.eyelids.Eye.
eyeball_centre``, radius ``EYEBALL_RADIUS`` x half the eye's width, fixed at rest; sclera light,
iris and pupil dark about the eye's forward axis). Without it the eye holes are empty and the
model cannot see the lids' opening (AU5) nor, on MakeHuman, tell it from the brows (recog10,
recog12). The figures of the two renders are not comparable.

``--units``: the scorer's sanity check (not a target): each MakeHuman expression unit
(``tests/data/mh_head_expression_units_caucasian.npz``, the sample's own vertex order) laid on
the MakeHuman workdir's rest (the first WORKDIR must be the MakeHuman sample) and scored
the same way; the table gives each unit's top AUs over neutral.

Writes ``benchmarks/results/<NAME>.json`` (default ``recognition``) and prints a table: per
head and view, per preset, recognised or not, the six scores and the top 5 blendshapes.
``--pictures DIR`` also writes each head's renders as a PNG strip (what the model saw).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent))

from _util import write_results  # noqa: E402

#: the views (degrees of yaw, + turns the subject's left cheek towards the camera)
VIEWS = {"front": 0.0, "yaw20": 20.0}
UNITS = HERE.parent / "tests" / "data" / "mh_head_expression_units_caucasian.npz"


def head_poses(workdir: Path):
    """(head, names (7,), skins (7, n, 3)) of the neutral face and the six presets, settled."""
    import expr_measure as em

    from faceforge.mpeg4.expressions import EXPRESSIONS

    head, mapping, _ = em.load_head(workdir)
    faps = np.zeros((1 + len(EXPRESSIONS), 68))
    for i, name in enumerate(EXPRESSIONS):
        faps[i + 1] = mapping.expressions[name]
    skins, _, _ = em.settle(head, mapping, faps)
    return head, ["neutral", *EXPRESSIONS], skins


def head_eyes(head):
    """The eyeballs of ``head`` at rest (:func:`faceforge.landmarks.blendshapes.eyeballs`), or
    None when it has no eye the lids know."""
    from faceforge.animation.eyelids import EYEBALL_RADIUS, find_eyes
    from faceforge.landmarks.blendshapes import eyeballs

    eyes = find_eyes(head.landmarks)
    if not eyes:
        return None
    return eyeballs(np.array([e.eyeball_centre for e in eyes]), np.array([EYEBALL_RADIUS * e.half for e in eyes]),
                    np.array([e.axes[2] for e in eyes]))


def score_poses(scorer, skins, faces, region, names, pictures=None, label="", eyes=None):
    """{view: {name: {scores, recognised, ...}}} for poses ``skins (k, n, 3)``, the first the
    neutral face; ``eyes`` (:func:`head_eyes`) drawn in each render when given."""
    from faceforge.landmarks import blendshapes as bs

    out = {}
    for view_name, yaw in VIEWS.items():
        view = bs.face_view(skins[0][region], yaw)
        images = [bs.grey_render(s, faces, view, eyes) for s in skins]
        if pictures is not None:
            from PIL import Image

            strip = np.concatenate(images, axis=1)
            Image.fromarray(strip).resize((strip.shape[1] // 2, strip.shape[0] // 2)).save(
                Path(pictures) / f"{label}_{view_name}.png")
        raw = [scorer.score(im) for im in images]
        rows = {}
        if raw[0] is None:
            out[view_name] = {"error": "no face found in the neutral render"}
            continue
        for name, shapes in zip(names[1:], raw[1:]):
            if shapes is None:
                rows[name] = {"found": False, "recognised": False}
                continue
            scores = bs.expression_scores(shapes, raw[0])
            top = sorted(((k, v) for k, v in shapes.items() if k != "_neutral"), key=lambda kv: -kv[1])[:5]
            delta = {k: v - raw[0][k] for k, v in shapes.items() if k != "_neutral"}
            top_delta = sorted(delta.items(), key=lambda kv: -kv[1])[:5]
            rows[name] = {"found": True, "read_as": bs.recognised(scores),
                          "recognised": bs.recognised(scores) == name if name in scores else None,
                          "scores": {k: round(v, 4) for k, v in scores.items()},
                          "top5": [[k, round(v, 3)] for k, v in top],
                          "top5_over_neutral": [[k, round(v, 3)] for k, v in top_delta]}
        rows["neutral_blendshapes"] = {k: round(v, 3) for k, v in raw[0].items()}
        out[view_name] = rows
    return out


def unit_poses(head):
    """(names, skins (1 + u, n, 3)) of the MakeHuman units laid on the head's rest (working
    order and frame), the rest first."""
    units = np.load(UNITS)
    deltas = units["deltas"].astype(np.float64)
    if deltas.shape[1] != len(head.user_index):
        raise SystemExit(f"--units: the first workdir has {len(head.user_index)} user vertices, "
                         f"the units {deltas.shape[1]}: give the MakeHuman sample first")
    skins = np.repeat(head.rest[None], 1 + len(deltas), axis=0)
    for k, d in enumerate(deltas):
        skins[k + 1, head.user_index] += d @ np.asarray(head.user_rotation).T
    return ["rest", *[str(n) for n in units["names"]]], skins


def unit_rows(scorer, head, region) -> dict:
    """Per unit and view: the top AUs and top 5 blendshapes over the rest render."""
    from faceforge.landmarks import blendshapes as bs

    names, skins = unit_poses(head)
    out = {}
    for view_name, yaw in VIEWS.items():
        view = bs.face_view(skins[0][region], yaw)
        raw = [scorer.score(bs.grey_render(s, head.faces, view)) for s in skins]
        rows = {}
        for name, shapes in zip(names[1:], raw[1:]):
            if shapes is None or raw[0] is None:
                rows[name] = None
                continue
            au, au0 = bs.au_scores(shapes), bs.au_scores(raw[0])
            d_au = sorted(((f"AU{a}", au[a] - au0[a]) for a in au), key=lambda kv: -kv[1])[:3]
            delta = {k: v - raw[0][k] for k, v in shapes.items() if k != "_neutral"}
            rows[name] = {"top_aus": [[k, round(v, 3)] for k, v in d_au],
                          "top5_over_neutral": [[k, round(v, 3)] for k, v in
                                                sorted(delta.items(), key=lambda kv: -kv[1])[:5]],
                          "expression_scores": {k: round(v, 3) for k, v in bs.expression_scores(shapes, raw[0]).items()}}
        out[view_name] = rows
    return out


def print_head(label: str, result: dict) -> None:
    for view_name, rows in result["views"].items():
        if "error" in rows:
            print(f"{label} {view_name}: {rows['error']}")
            continue
        n_ok = sum(bool(r.get("recognised")) for k, r in rows.items() if k != "neutral_blendshapes")
        print(f"{label} {view_name}: {n_ok} of 6 recognised")
        for name, r in rows.items():
            if name == "neutral_blendshapes":
                continue
            if not r["found"]:
                print(f"  {name:9s} no face found")
                continue
            sc = " ".join(f"{k[:4]} {v:+.3f}" for k, v in r["scores"].items())
            top = ", ".join(f"{k} {v:.2f}" for k, v in r["top5"])
            print(f"  {name:9s} {'YES' if r['recognised'] else 'no ':3s} as {r['read_as']:8s} | {sc} | {top}")


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    ap.add_argument("workdirs", nargs="+", type=Path, metavar="WORKDIR")
    ap.add_argument("--out", default="recognition", help="results file stem (benchmarks/results/NAME.json)")
    ap.add_argument("--pictures", type=Path, default=None, help="write the renders the model saw here")
    ap.add_argument("--units", action="store_true", help="also score the MakeHuman units (first WORKDIR)")
    ap.add_argument("--eyes", action="store_true", help="draw eyeballs behind the lids")
    args = ap.parse_args(argv)
    from faceforge.landmarks.blendshapes import BlendshapeScorer
    from faceforge.viz.contact_sheet import face_region

    for w in args.workdirs:
        if not (w / "bind").is_dir():
            raise SystemExit(f"faceforge: error: {w}: not a bound workdir")
    if args.pictures:
        args.pictures.mkdir(parents=True, exist_ok=True)
    results, units = {}, None
    with BlendshapeScorer() as scorer:
        for i, w in enumerate(args.workdirs):
            t0 = time.perf_counter()
            head, names, skins = head_poses(w)
            region = face_region(head.rest, head.landmarks)
            region = np.ones(len(head.rest), bool) if region is None else region
            eyes = head_eyes(head) if args.eyes else None
            results[w.name] = {"views": score_poses(scorer, skins, head.faces, region, names, args.pictures, w.name,
                                                    eyes)}
            results[w.name]["seconds"] = round(time.perf_counter() - t0, 1)
            print_head(w.name, results[w.name])
            if args.units and i == 0:
                units = unit_rows(scorer, head, region)
    summary = {h: {v: sum(bool(r.get("recognised")) for k, r in rows.items() if k != "neutral_blendshapes")
                   for v, rows in res["views"].items()} for h, res in results.items()}
    print("recognised of 6:", summary)
    out = {"rule": "score(expr) = mean over its FACS AUs of (AU score - neutral AU score); AU score = mean "
                   "of its ARKit blendshapes; recognised when the intended expression scores highest of six",
           "views_yaw_deg": VIEWS, "eyes": args.eyes, "recognised_of_6": summary, "heads": results}
    if units is not None:
        out["units_sanity"] = units
        for name, r in units["front"].items():
            if r is not None:
                print(f"  unit {name:32s} {r['top_aus']}  {r['top5_over_neutral'][:3]}")
    write_results(args.out, out)
    return out


if __name__ == "__main__":
    main()
