"""Rigid head motion from the MPEG-4 head FAPs 48-50 (head_pitch, head_yaw, head_roll).

The three FAPs turn the whole head about the top of the spine (FDP 7.1), in angle units
(AU, 1e-5 rad). In faceforge's head frame (+X the subject's left, +Y up, +Z forward):

* head_pitch (48), positive *down*: about +X, the face (+Z) turns towards -Y;
* head_yaw (49), positive *left*: about +Y, the face turns towards +X;
* head_roll (50), positive *right*: about +Z, the top of the head (+Y) tilts towards -X.

They compose in the usual yaw-pitch-roll (Tait-Bryan) order, ``R = R_yaw @ R_pitch @ R_roll``:
roll in the head's own frame, then pitch, then yaw. The simulation runs in the head's frame;
the turn is applied to the finished frames, so skull, muscles and skin are turned as one.

Skin below the skull (a neck, a bust's shoulders) is not part of the head: :func:`neck_weights`
fades the turn out below the skull's lowest point, so the base of a neck stays where it is and
a face that ends at the chin turns rigidly.
"""

from __future__ import annotations

import numpy as np

#: FAP numbers of head_pitch, head_yaw and head_roll
HEAD_FAPS = (48, 49, 50)

#: radians per angle unit (AU)
AU = 1e-5


def head_angles(faps: np.ndarray) -> np.ndarray:
    """``(F, 3) float64`` (pitch, yaw, roll) in radians from FAP frames ``faps (F, 68)``
    (column k = FAP k + 1, in AU; NaN counts as 0)."""
    faps = np.atleast_2d(np.asarray(faps, dtype=np.float64))
    if faps.shape[1] < max(HEAD_FAPS):
        raise ValueError(f"faps must be (F, 68), got {faps.shape}")
    return np.nan_to_num(faps[:, [f - 1 for f in HEAD_FAPS]]) * AU


def head_rotations(angles: np.ndarray) -> np.ndarray:
    """``(F, 3, 3)`` rotation matrices ``R_yaw @ R_pitch @ R_roll`` for ``angles (F, 3)``
    (pitch, yaw, roll) in radians (see the module docstring for the axes and signs)."""
    a = np.atleast_2d(np.asarray(angles, dtype=np.float64))
    cp, sp = np.cos(a[:, 0]), np.sin(a[:, 0])
    cy, sy = np.cos(a[:, 1]), np.sin(a[:, 1])
    cr, sr = np.cos(a[:, 2]), np.sin(a[:, 2])
    one, zero = np.ones(len(a)), np.zeros(len(a))
    pitch = np.stack([np.stack([one, zero, zero], -1), np.stack([zero, cp, -sp], -1),
                      np.stack([zero, sp, cp], -1)], 1)
    yaw = np.stack([np.stack([cy, zero, sy], -1), np.stack([zero, one, zero], -1),
                    np.stack([-sy, zero, cy], -1)], 1)
    roll = np.stack([np.stack([cr, -sr, zero], -1), np.stack([sr, cr, zero], -1),
                     np.stack([zero, zero, one], -1)], 1)
    return yaw @ pitch @ roll


def neck_weights(rest: np.ndarray, skull_bottom: float, span: float) -> np.ndarray:
    """``(n,) float64`` in [0, 1]: how much of the head's turn each rest vertex ``rest (n, 3)``
    takes. 1 at or above the height ``skull_bottom`` (+Y, the skull's lowest point), fading
    linearly to 0 at ``span`` below it (skin units); ``span <= 0``: 1 everywhere."""
    y = np.asarray(rest, dtype=np.float64).reshape(-1, 3)[:, 1]
    if not span > 0.0:
        return np.ones(len(y))
    return np.clip((y - (skull_bottom - span)) / span, 0.0, 1.0)


def turn_head(frames: np.ndarray, angles: np.ndarray, pivot: np.ndarray,
              weights: np.ndarray | None = None) -> np.ndarray:
    """Frames ``(F, n, 3)`` turned about ``pivot (3,)`` by ``angles (F, 3)`` (pitch, yaw, roll;
    radians): ``pivot + R(w_i a_f) (x - pivot)`` for vertex ``i`` of frame ``f``, with
    ``weights (n,)`` in [0, 1] (:func:`neck_weights`; None: all 1, a rigid turn). A new array;
    frames whose three angles are all zero, and vertices of weight 0, are copied bit for bit."""
    frames = np.asarray(frames)
    angles = np.atleast_2d(np.asarray(angles, dtype=np.float64))
    if angles.shape != (len(frames), 3):
        raise ValueError(f"angles must be ({len(frames)}, 3), got {angles.shape}")
    n = frames.shape[1] if frames.ndim == 3 else 0
    w = np.ones(n) if weights is None else np.asarray(weights, dtype=np.float64).reshape(-1)
    if len(w) != n:
        raise ValueError(f"weights must be ({n},), got {w.shape}")
    c = np.asarray(pivot, dtype=np.float64).reshape(3)
    out = np.array(frames, copy=True)
    full, part = np.flatnonzero(w == 1.0), np.flatnonzero((w > 0.0) & (w < 1.0))
    for f in np.flatnonzero(np.any(angles != 0.0, axis=1)):
        x = frames[f]
        out[f, full] = ((x[full] - c) @ head_rotations(angles[f])[0].T + c).astype(out.dtype)
        if len(part):                     # the neck: each vertex its share of the turn
            r = head_rotations(w[part, None] * angles[f])
            out[f, part] = (np.einsum("nij,nj->ni", r, x[part] - c) + c).astype(out.dtype)
    return out
