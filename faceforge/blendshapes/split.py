"""Left/right shape pairs split from one bilateral pose (``bake.split_pairs``, issue 27).

An engine mixes ``mouthSmileLeft`` and ``mouthSmileRight`` by adding their displacements. Settled one
side at a time, each shape also moves the middle of the face (the lip ring, the mentalis, the
nose's skin are one tissue): the sum of the two counts the middle twice. On the MakeHuman sample
``mouthPressLeft`` + ``Right`` peaked at 2.0x the two sides pressed together, ``mouthLowerDown`` at
1.9x; a Live Link take of ``mouthLowerDownLeft`` and ``-Right`` at 1.0 played through the muscles
solved back (unregularised) to 0.71 / 0.69 of each, and a replayed joy take came back with its
lowered lip at half its weight (docs/notes/split20.md). Split, the pair is the bilateral pose (both
sides' muscles together, solved against both sides' FAP targets at once: :func:`bilateral_spec`)
settled once and cut across the midsagittal plane by a smooth ramp: the
left shape is its displacement times :func:`side_weights`, the right the rest, so the two add up to
the bilateral pose exactly, as a FACS-split rig's do. A one-sided weight then moves one half of the
bilateral pose (not the one-sided physics, whose middle moves less).

The pair's controls split the same way (:func:`split_controls`): each side's own muscles to its
shape, the midline ones (the orbicularis oris, the mentalis) half to each, so that ``animate --arkit``
playing both at full plays the bilateral pose.
"""

from __future__ import annotations

import numpy as np

#: the blend's half-width across the midline (mm, an average adult's; scaled by the head's ES0):
#: the left weight rises from 0 to 1 over twice this, centred on the plane
BLEND_MM = 8.0


def side_weights(side: np.ndarray, width: float) -> np.ndarray:
    """(n,) in [0, 1]: the left shape's share of each vertex's motion from its signed distance
    ``side (n,)`` to the midsagittal plane (positive: the subject's left), a smoothstep from 0 at
    ``-width`` to 1 at ``+width`` (0.5 on the plane; a mirror pair of vertices gets ``w`` and
    ``1 - w``). ``width`` > 0, in the same units."""
    t = np.clip(0.5 + 0.5 * np.asarray(side, dtype=float) / float(width), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def bilateral_controls(left: np.ndarray, right: np.ndarray, sided: np.ndarray) -> np.ndarray:
    """(m,) contractions of the two sides' poses together: ``left``, ``right`` (m,) the left and right
    shapes' contractions, ``sided`` (m,) bool the one-sided muscles (``_L`` / ``_R``), summed (each is
    in one pose only); a midline muscle both poses use takes the larger of the two (one muscle)."""
    left, right = np.asarray(left, dtype=float), np.asarray(right, dtype=float)
    return np.where(np.asarray(sided, bool), left + right, np.maximum(left, right))


def split_controls(both: np.ndarray, left_cols: np.ndarray, right_cols: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The bilateral contractions ``both (m,)`` shared between the left and right shapes: each side's
    own muscles (``left_cols``, ``right_cols`` (m,) bool) to its shape, the others half to each, so
    that the two add up to ``both``. Returns (left (m,), right (m,))."""
    both = np.asarray(both, dtype=float)
    left_cols, right_cols = np.asarray(left_cols, bool), np.asarray(right_cols, bool)
    mid = ~(left_cols | right_cols)
    left = np.where(left_cols, both, 0.0) + np.where(mid, 0.5 * both, 0.0)
    right = np.where(right_cols, both, 0.0) + np.where(mid, 0.5 * both, 0.0)
    return left, right


def split_frame(rest: np.ndarray, bilateral: np.ndarray, left_weight: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The bilateral frame's displacement from ``rest`` (n, 3) cut by ``left_weight`` (n,)
    (:func:`side_weights`): (left (n, 3), right (n, 3)) frames whose displacements add up to the
    bilateral one."""
    rest = np.asarray(rest, dtype=float)
    d = np.asarray(bilateral, dtype=float) - rest
    w = np.asarray(left_weight, dtype=float)[:, None]
    return rest + w * d, rest + (1.0 - w) * d


def midline_side(vertices: np.ndarray, landmarks: dict) -> np.ndarray | None:
    """(n,) signed distance of ``vertices`` (n, 3) to the plane halfway between the pupils (FDP 3.5,
    the subject's left, and 3.6), normal to the line between them, positive on the left; None
    without both pupils."""
    if "3.5" not in landmarks or "3.6" not in landmarks:
        return None
    a, b = np.asarray(landmarks["3.5"], dtype=float), np.asarray(landmarks["3.6"], dtype=float)
    n = a - b
    if not np.linalg.norm(n) > 0.0:
        return None
    n = n / np.linalg.norm(n)
    return (np.asarray(vertices, dtype=float) - 0.5 * (a + b)) @ n


def bilateral_spec(stem: str, left, right):
    """The :class:`faceforge.blendshapes.arkit.ShapeSpec` of a pair's two sides at once, named ``stem``
    (no side: the bake's solve then moves mirror-twin controls together): both sides' FAP targets
    (a FAP both name: the larger request), controls and lids."""
    from faceforge.blendshapes.arkit import ShapeSpec

    faps = dict(left.faps)
    for f, v in right.faps.items():
        if abs(v) > abs(faps.get(f, 0.0)):
            faps[f] = v
    lids = {**left.lids, **right.lids}
    controls = tuple(dict.fromkeys(left.controls + right.controls))
    return ShapeSpec(stem, faps, controls, lids, {}, left.approximation)
