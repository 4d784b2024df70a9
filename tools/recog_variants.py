"""What does the face-reading model see in a preset and its variants? (issue 25 item 4)

Usage::

    PYTHONPATH=. python tools/recog_variants.py WORKDIR VARIANTS.py [--pictures DIR]

WORKDIR is fitted, bound and calibrated (as ``benchmarks/bench_recognition.py`` wants it).
VARIANTS.py is a Python file defining ``VARIANTS = {label: (preset, {fap: value}, muscles)}``:
``preset`` a name of the template's ``expressions:`` (or None for all zeros), the FAP values
(MPEG-4 numbers 3..68, the template's units) laid over it, and optionally a tuple of muscles
whose contraction is set to 0 after the mapping (a diagnostic: "fear without the zygomaticus").
Each variant is settled with the neutral face as the bench settles the presets (held until the
skin stops moving, lids laid over), rendered front and turned 20 degrees, and scored by the
bench's rule; printed per variant: what it reads as, the six expression scores, the folded
skin edges (:func:`faceforge.animation.checks.folded_edges`) and every rule AU over neutral
with the four blendshapes that rose most. Reproduces the bench's figures for the presets
themselves (``{name: (name, {})}``); nothing is written but the optional pictures.

recog22 (ICT at main b3e1551): fear reads surprise front (AU1 +0.49, AU4 -0.44, AU20 0.00);
the stretch FAP alone reads as joy (mouthSmile +0.55), and still +0.72 with the zygomaticus
major zeroed: a lateral pull of ICT's corners is a smile to the model.
"""

from __future__ import annotations

import argparse
import runpy
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "benchmarks"))
sys.path.insert(0, str(HERE.parent))

#: the rule's AUs, in the order printed
AUS = (1, 2, 4, 5, 6, 7, 9, 12, 15, 16, 20, 23, 26)


def variant_rows(expressions: dict, variants: dict) -> tuple[list, np.ndarray, list]:
    """(labels, FAP rows (1 + v, 68), muscles to zero per row) of ``variants`` (see the module
    doc) over the template's ``expressions {name: (68,) FAP values}``; row 0 is neutral (zeros).
    Column k is FAP k + 1, as everywhere (``animation.fap_mapping``)."""
    labels, rows, zeros = ["neutral"], [np.zeros(68)], [()]
    for label, spec in variants.items():
        preset, over = spec[0], spec[1]
        row = np.array(expressions[preset], dtype=float) if preset else np.zeros(68)
        for fap, value in over.items():
            if not 3 <= int(fap) <= 68:
                raise ValueError(f"{label}: FAP {fap} is not a low-level FAP (3..68)")
            row[int(fap) - 1] = float(value)
        labels.append(label)
        rows.append(row)
        zeros.append(tuple(spec[2]) if len(spec) > 2 else ())
    return labels, np.array(rows), zeros


def zero_muscles(contractions: np.ndarray, names, zeros) -> np.ndarray:
    """A copy of ``contractions (k, m)`` with row i's muscles ``zeros[i]`` (names of ``names``)
    set to 0."""
    out = np.array(contractions, dtype=float)
    index = {n: j for j, n in enumerate(names)}
    for i, muscles in enumerate(zeros):
        for m in muscles:
            out[i, index[m]] = 0.0
    return out


def settle_variants(head, mapping, rows: np.ndarray, zeros) -> np.ndarray:
    """Settled skins (k, n, 3) of FAP ``rows (k, 68)`` as the bench settles the presets."""
    from faceforge.animation.controls import controls
    from faceforge.animation.statics import SettleSettings, settle

    c, jaw = controls(mapping, rows, head)
    c = zero_muscles(c, list(head.controls), zeros)
    skins = settle(head.rig, c, jaw, 25.0, SettleSettings.from_config(head._bench_config))
    head.rig.reset()
    return head._bench_lids.apply(skins, rows) if head._bench_lids is not None else skins


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    ap.add_argument("workdir", type=Path)
    ap.add_argument("variants", type=Path)
    ap.add_argument("--pictures", type=Path, default=None, help="write each view's renders here as a strip")
    args = ap.parse_args(argv)
    import expr_measure as em
    from bench_recognition import VIEWS

    from faceforge.animation.checks import folded_edges
    from faceforge.landmarks import blendshapes as bs
    from faceforge.viz.contact_sheet import face_region

    head, mapping, _ = em.load_head(args.workdir)
    labels, rows, zeros = variant_rows(mapping.expressions, runpy.run_path(str(args.variants))["VARIANTS"])
    skins = settle_variants(head, mapping, rows, zeros)
    folds = folded_edges(head.rest, skins, head.faces).sum(axis=1)
    region = face_region(head.rest, head.landmarks)
    region = np.ones(len(head.rest), bool) if region is None else region
    with bs.BlendshapeScorer() as scorer:
        for view_name, yaw in VIEWS.items():
            view = bs.face_view(skins[0][region], yaw)
            images = [bs.grey_render(s, head.faces, view) for s in skins]
            if args.pictures is not None:
                from PIL import Image

                args.pictures.mkdir(parents=True, exist_ok=True)
                Image.fromarray(np.concatenate(images, axis=1)).save(
                    args.pictures / f"{args.workdir.name}_{view_name}.png")
            raw = [scorer.score(im) for im in images]
            print(f"== {args.workdir.name} {view_name}")
            if raw[0] is None:
                print("no face found in the neutral render")
                continue
            au0 = bs.au_scores(raw[0])
            for label, shapes, f in zip(labels[1:], raw[1:], folds[1:]):
                if shapes is None:
                    print(f"{label:16s} no face found")
                    continue
                scores = bs.expression_scores(shapes, raw[0])
                au = bs.au_scores(shapes)
                rose = sorted(((k, v - raw[0][k]) for k, v in shapes.items() if k != "_neutral"),
                              key=lambda kv: -kv[1])[:4]
                print(f"{label:16s} reads {bs.recognised(scores):8s} | "
                      + " ".join(f"{k[:3]} {v:+.3f}" for k, v in scores.items()) + f" | folded {int(f)}")
                print("    " + " ".join(f"AU{a} {au[a] - au0[a]:+.2f}" for a in AUS) + " | "
                      + ", ".join(f"{k} {v:+.2f}" for k, v in rose))


if __name__ == "__main__":
    main()
