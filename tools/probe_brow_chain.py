"""Where is a deep brow muscle's motion lost on its way to the skin? (issue 7, eyebrow rows)

Usage::

    PYTHONPATH=. python tools/probe_brow_chain.py WORKDIR [--c 1.0] [--frames 40]

WORKDIR holds a ``fit`` and a ``bind`` stage. Each deep brow muscle (depressor supercilii,
lateral orbicularis oculi, corrugator) is contracted alone at ``c`` (static pose, ``frames``
frames) and the displacement along the direction it should pull, in the FAPU of the row
(ENS down, ES toward the midline), is printed link by link near the FDP it acts on (within
a quarter of ENS0 of it):

* ``deep``: the deep muscle's own vertices;
* ``under``: the deep surface under the overlying frontalis' bound bottom particles (the
  nearest deep-muscle vertex), the frontalis' position ``target`` of those particles
  (its action lines resampled on the deep layer) and the ``particle`` itself;
* ``anchor``: the skin anchor of the FDP's vertex (its body) and the mean of the anchors
  within the radius, per body;
* ``skin``: the FDP's skin vertex (as simulated; the influence map is 1 on the brows).

MakeHuman, c = 1 (main at 215794e): depressor supercilii L deep 122, under the frontalis 130,
frontalis target 58, particle 46, FDP 4.1 anchor (frontalis_inner_L) 60, skin 20.7 ENS; half
of the brow skin near 4.1 is bound to the cranium.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

#: (deep muscle, overlying frontalis, FDP, direction, FAPU)
CASES = (
    ("depressor_supercilii_L", "frontalis_inner_L", "4.1", (0.0, -1.0, 0.0), "ENS"),
    ("depressor_supercilii_R", "frontalis_inner_R", "4.2", (0.0, -1.0, 0.0), "ENS"),
    ("orbicularis_oculi_L", "frontalis_outer_L", "4.5", (0.0, -1.0, 0.0), "ENS"),
    ("orbicularis_oculi_R", "frontalis_outer_R", "4.6", (0.0, -1.0, 0.0), "ENS"),
    ("corrugator_supercilii_L", "frontalis_inner_L", "4.1", (-1.0, 0.0, 0.0), "ES"),
    ("corrugator_supercilii_R", "frontalis_inner_R", "4.2", (1.0, 0.0, 0.0), "ES"),
    ("corrugator_supercilii_L", "frontalis_outer_L", "4.3", (-1.0, 0.0, 0.0), "ES"),
    ("corrugator_supercilii_R", "frontalis_outer_R", "4.4", (1.0, 0.0, 0.0), "ES"),
)


def _layer_of(system, name):
    """(layer, index in it, Muscle) of muscle ``name`` in a MusculoskeletalSystem."""
    for layer in system._layers:
        for i, m in enumerate(layer.muscles):
            if m.name == name:
                return layer, i, m
    raise KeyError(name)


def probe(workdir: Path, c: float = 1.0, frames: int = 40, sets=()) -> list[dict]:
    """One dict per case of :data:`CASES` (keys as the module docstring's links)."""
    from faceforge.io.config import load_config
    from faceforge.animation.rig import BoundHead

    head = BoundHead(workdir / "fit", workdir / "bind", load_config(sets=list(sets)))
    system, names, binding = head.system, list(head.muscle_names), head.skin.binding
    radius = 0.25 * head.fapu.unit("ENS") * 1024.0
    rows = []
    for deep, top, fdp, d, unit in CASES:
        if deep not in names or top not in names or fdp not in head.fdp_vertex:
            continue
        d = np.asarray(d, float)
        u = head.fapu.unit(unit)
        vid = head.fdp_vertex[fdp]
        p0 = head.rest[vid]
        layer, i, m = _layer_of(system, top)
        head.rig.reset()
        t0 = layer.control.position_targets[layer.slots[i]].copy()
        ctr = dict.fromkeys(names, 0.0)
        ctr[deep] = c
        for _ in range(frames):
            system.step(ctr, None, 1.0 / 25.0)
            x = head.rig.skin(None, None, 1.0 / 25.0)
        t = layer.control.position_targets[layer.slots[i]]
        rb, xb = m.rest_positions[m.bound], system.positions(top)[m.bound]
        near = np.linalg.norm(rb - p0, axis=1) < radius
        dr, dx = system.rest_positions(deep), system.positions(deep)
        under = np.array([np.argmin(np.linalg.norm(dr - p, axis=1)) for p in rb[near]], dtype=int)
        deep_near = np.linalg.norm(dr - p0, axis=1) < radius
        anchors = head.skin.anchor_targets(system)
        k = int(np.searchsorted(binding.vertex_ids, vid))
        own = k < len(binding.vertex_ids) and binding.vertex_ids[k] == vid
        close = np.linalg.norm(head.rest[binding.vertex_ids] - p0, axis=1) < radius
        per_body = {}
        for b in np.unique(binding.body[close]):
            sel = close & (binding.body == b)
            per_body[binding.body_names[b]] = (int(sel.sum()),
                                               float(((anchors[sel] - binding.points[sel]) @ d / u).mean()))
        rows.append(dict(
            muscle=deep, over=top, fdp=fdp, fapu=unit,
            deep=float(((dx - dr)[deep_near] @ d / u).mean()) if deep_near.any() else float("nan"),
            under=float(((dx[under] - dr[under]) @ d / u).mean()) if near.any() else float("nan"),
            target=float(((t - t0)[near] @ d / u).mean()) if near.any() else float("nan"),
            particle=float(((xb - rb)[near] @ d / u).mean()) if near.any() else float("nan"),
            anchor_body=binding.body_names[binding.body[k]] if own else None,
            anchor=float((anchors[k] - binding.points[k]) @ d / u) if own else float("nan"),
            anchors=per_body, skin=float((x[vid] - p0) @ d / u)))
    head.rig.reset()
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("workdir", type=Path)
    ap.add_argument("--c", type=float, default=1.0)
    ap.add_argument("--frames", type=int, default=40)
    ap.add_argument("--set", action="append", default=[], help="config override KEY=VALUE")
    args = ap.parse_args(argv)
    for r in probe(args.workdir, args.c, args.frames, args.set):
        print(f"{r['muscle']:24s} {r['fdp']} {r['fapu']:3s} deep {r['deep']:6.1f}  {r['over']} under "
              f"{r['under']:6.1f} target {r['target']:6.1f} particle {r['particle']:6.1f}  anchor "
              f"{r['anchor']:6.1f} ({r['anchor_body']})  skin {r['skin']:6.1f}")
        print("    anchors near: " + ", ".join(f"{b} {n} x {a:.1f}" for b, (n, a) in r["anchors"].items()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
