"""Head orientation: the rotation between a mesh's own axes and faceforge's frame.

faceforge works in one frame: +Y up, the face looking along +Z, the subject's left at +X
(right-handed, the MPEG-4 neutral face). A head in another frame is described by two
signed axes of *its* coordinates, ``up`` and ``forward`` (e.g. Blender's Z-up world with
the face toward -Y: up ``+z``, forward ``-y``). :func:`frame_rotation` turns them into the
proper rotation ``R (3, 3)`` with::

    p_faceforge = R @ p_user          # rows of R: the user's left, up and forward
    p_user      = R.T @ p_faceforge   # for arrays of row vectors: p @ R.T and p @ R

Between axis-aligned frames ``R`` is a signed permutation, so both directions are exact
in floating point (every product is by 0 or +-1): a head rotated by such a turn is fitted
and simulated to the same bits as the unrotated one.

:func:`estimate_frame` guesses the frame of a head from a few points of known meaning
(pairs of left/right points, a low and a high point), and :func:`snap_to_axes` rounds it
to the nearest axis-aligned frame; :func:`straightening_rotation` is the (general, not exact)
rotation that takes a measured frame onto a reference one, for a head turned off the axes in
its file. Pure functions on arrays: no FDP names here
(:mod:`faceforge.io.landmarks` chooses the points).
"""

from __future__ import annotations

import numpy as np

__all__ = ["AXES", "parse_axis", "axis_name", "frame_rotation", "estimate_frame", "snap_to_axes",
           "angle_between", "straightening_rotation"]

#: the six signed axes by name
AXES = {"+x": (1.0, 0.0, 0.0), "-x": (-1.0, 0.0, 0.0), "+y": (0.0, 1.0, 0.0),
        "-y": (0.0, -1.0, 0.0), "+z": (0.0, 0.0, 1.0), "-z": (0.0, 0.0, -1.0)}


def parse_axis(text) -> np.ndarray:
    """``"+Z"``, ``"-y"``, ``"x"`` (= ``+x``) -> unit vector (3,) float. Raises ValueError."""
    key = str(text).strip().lower()
    if len(key) == 1:
        key = "+" + key
    if key not in AXES:
        raise ValueError(f"axis {text!r}: expected one of {', '.join(a.upper() for a in AXES)}")
    return np.array(AXES[key])


def axis_name(vector) -> str:
    """The signed axis name (``"+Y"``) of an axis-aligned unit vector (3,)."""
    v = np.asarray(vector, dtype=float)
    i = int(np.argmax(np.abs(v)))
    return ("+" if v[i] > 0 else "-") + "XYZ"[i]


def frame_rotation(up, forward) -> np.ndarray:
    """Rotation ``R (3, 3)`` taking the user's frame to faceforge's: ``R @ up = +Y``,
    ``R @ forward = +Z``, ``R @ (up x forward) = +X`` (the subject's left).

    ``up``, ``forward``: (3,) vectors in the user's coordinates (normalised here); they
    must be perpendicular (to 1e-6 after normalising). Raises ValueError.
    """
    u = np.asarray(up, dtype=float)
    f = np.asarray(forward, dtype=float)
    if u.shape != (3,) or f.shape != (3,):
        raise ValueError(f"up and forward must be (3,) vectors, got {u.shape} and {f.shape}")
    nu, nf = np.linalg.norm(u), np.linalg.norm(f)
    if not (nu > 0 and nf > 0):
        raise ValueError("up and forward must be non-zero")
    u, f = u / nu, f / nf
    if abs(float(u @ f)) > 1e-6:
        raise ValueError(f"up {np.round(u, 3).tolist()} and forward {np.round(f, 3).tolist()} "
                         "are not perpendicular")
    left = np.cross(u, f)
    return np.vstack([left, u, f])


def estimate_frame(left_points, right_points, low_points, high_points) -> tuple[np.ndarray, np.ndarray]:
    """Up and forward (unit (3,) vectors, user coordinates) from points of known meaning.

    ``left_points (k, 3)`` and ``right_points (k, 3)``: k >= 1 mirror pairs (subject's left
    and right); ``low_points (a, 3)``, ``high_points (b, 3)``: points low and high on the
    face (chin; eyes). Left is the mean left-minus-right difference; up the high-minus-low
    difference made perpendicular to it; forward = left x up (so that up x forward = left).
    Raises ValueError when the points do not span a frame.
    """
    lp, rp = np.atleast_2d(np.asarray(left_points, float)), np.atleast_2d(np.asarray(right_points, float))
    if lp.shape != rp.shape or lp.shape[1:] != (3,) or len(lp) == 0:
        raise ValueError(f"left and right points must be matching (k, 3) arrays, got {lp.shape}, {rp.shape}")
    left = (lp - rp).mean(axis=0)
    rise = np.atleast_2d(np.asarray(high_points, float)).mean(axis=0) - \
        np.atleast_2d(np.asarray(low_points, float)).mean(axis=0)
    nl = np.linalg.norm(left)
    if not nl > 0:
        raise ValueError("the left and right points coincide: no left-right axis")
    left /= nl
    up = rise - (rise @ left) * left
    nu = np.linalg.norm(up)
    if not nu > 1e-9 * max(np.linalg.norm(rise), 1e-300):
        raise ValueError("the high and low points do not rise across the left-right axis")
    up /= nu
    return up, np.cross(left, up)


def snap_to_axes(up, forward) -> tuple[np.ndarray, np.ndarray]:
    """The axis-aligned frame nearest to ``(up, forward)``: each rounded to its dominant
    signed axis. Raises ValueError when both round to the same axis (a frame tilted by
    about 45 degrees, which no axis-aligned frame describes)."""
    out = []
    for v in (up, forward):
        v = np.asarray(v, dtype=float)
        i = int(np.argmax(np.abs(v)))
        a = np.zeros(3)
        a[i] = 1.0 if v[i] > 0 else -1.0
        out.append(a)
    if abs(out[0] @ out[1]) > 0:
        raise ValueError("the head is tilted about 45 degrees between two axes: give its up and "
                         "forward axes explicitly")
    return out[0], out[1]


def angle_between(a, b) -> float:
    """Angle in degrees between two (3,) vectors."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    c = a @ b / (np.linalg.norm(a) * np.linalg.norm(b))
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


def straightening_rotation(up, forward, ref_up, ref_forward) -> np.ndarray:
    """Rotation ``R (3, 3)`` with ``R @ up = ref_up`` and ``R @ forward = ref_forward``.

    ``up``, ``forward``: a head's frame in the user's coordinates (unit, perpendicular, e.g.
    from :func:`estimate_frame`); ``ref_up``, ``ref_forward``: where that frame should lie in
    faceforge's frame (the template's own landmark frame, a few degrees off the axes). Used as
    ``p_faceforge = R @ p_user`` like :func:`frame_rotation`; a proper rotation, not a signed
    permutation, so not exact in floating point. Raises ValueError as :func:`frame_rotation`.
    """
    return frame_rotation(ref_up, ref_forward).T @ frame_rotation(up, forward)
