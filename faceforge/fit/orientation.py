"""How a user's head is turned into head space before the fit (+Y up, facing +Z).

``fit.orientation``: ``auto`` takes the landmark file's ``orientation: {up, forward}`` or, without
one, the frame its landmarks span, snapped to the nearest axes; or ``UP,FORWARD`` such as
``+Z,-Y``. The rotation is a signed permutation (exact); ``animate`` turns the frames back.

A head turned off the axes in its file (a scan's yaw and pitch): with ``auto`` and no
``orientation`` in the landmark file, when the landmarks' frame lies more than
``fit.straighten_deg`` from the template's own landmark frame once snapped, the head is turned
by the landmarks' frame onto the template's (a general rotation, not exact): it is then fitted,
simulated and drawn upright, its head turns (FAPs 48-50) are about its own axes, and the
animation is still written back in the file's frame.
"""

from __future__ import annotations

from pathlib import Path

from faceforge.io.config import check_orientation


class HeadOrientation:
    """How the user's mesh is turned into head space (see the module docstring).

    rotation : (3, 3) float, head space = user coordinates ``@ rotation.T``
    up, forward : the mesh's own axes, as names (``"+Z"``)
    source : "config" (``fit.orientation``), "landmark file" (its ``orientation``),
        "landmarks" (the frame they span, snapped to the axes) or "default" (too few
        landmarks to tell: faceforge's own frame)
    tilt_deg : largest angle between the landmarks' own up and forward and those used,
        degrees (NaN when the landmarks do not span a frame)
    straightened_deg : when the head was turned by its landmarks' frame (``fit.straighten_deg``),
        the angle of that turn beyond the snapped axes, degrees; else None
    """

    def __init__(self, rotation, up: str, forward: str, source: str, tilt_deg: float,
                 straightened_deg: float | None = None):
        self.rotation, self.up, self.forward, self.source, self.tilt_deg = rotation, up, forward, source, tilt_deg
        self.straightened_deg = straightened_deg

    @property
    def identity(self) -> bool:
        import numpy as np

        return bool(np.array_equal(self.rotation, np.eye(3)))

    def describe(self) -> str:
        turned = "" if self.straightened_deg is None else \
            f", turned a further {self.straightened_deg:.1f} degrees by its landmarks' frame (fit.straighten_deg)"
        return (f"the head is {self.up} up and faces {self.forward} (from the {self.source}{turned}); it is "
                f"fitted and simulated turned to +Y up, facing +Z, and the animation is written back in its own frame")

    def as_dict(self) -> dict:
        return {"up": self.up, "forward": self.forward, "source": self.source,
                "landmark_tilt_deg": None if self.tilt_deg != self.tilt_deg else round(float(self.tilt_deg), 3),
                "straightened_deg": None if self.straightened_deg is None else round(float(self.straightened_deg), 3),
                "rotation": self.rotation.tolist()}


def user_rotation(fit_dir):
    """``user_rotation (3, 3)`` of a fit stage folder's fit.npz (identity for fits made
    before faceforge turned heads): head space = the user's frame ``@ R.T``."""
    import numpy as np

    from faceforge.io.stagefiles import load_npz

    fit = load_npz(Path(fit_dir) / "fit.npz")
    return np.asarray(fit["user_rotation"], dtype=float) if "user_rotation" in fit else np.eye(3)


#: the landmarks' own up may differ from the declared or snapped one by at most this (degrees)
MAX_ORIENTATION_TILT_DEG = 50.0


def head_orientation(setting: str, raw, vertices, reference=None, straighten_deg=None) -> HeadOrientation:
    """The orientation of a head (``fit.orientation``; see the module docstring).

    ``raw``: :class:`faceforge.io.landmarks.RawLandmarks` read from the file;
    ``vertices (n, 3)``: the user's mesh (the file's vertex ids refer to it);
    ``reference``: ``(up (3,), forward (3,))``, the template's landmark frame in head space,
    and ``straighten_deg`` (degrees, None = never): with ``auto`` and no frame in the file, a
    head whose snapped landmark frame is further than this from ``reference`` is turned onto it
    (:func:`faceforge.geometry.orientation.straightening_rotation`). Raises
    LandmarkError when the frame cannot be told, or when the given one contradicts the
    landmarks by more than :data:`MAX_ORIENTATION_TILT_DEG`.
    """
    import numpy as np

    from faceforge.exceptions import LandmarkError
    from faceforge.geometry.orientation import (angle_between, axis_name, frame_rotation, parse_axis,
                                                snap_to_axes)
    from faceforge.io.landmarks import landmark_frame

    if setting != "auto":
        try:
            check_orientation(setting)
            up, forward = (parse_axis(w) for w in setting.split(","))
        except ValueError as exc:
            from faceforge.exceptions import ConfigError

            raise ConfigError(f"fit.orientation: expected {exc}, got {setting!r}") from None
        source = "config"
    elif raw.orientation is not None:
        (up, forward), source = raw.orientation, "landmark file"
    else:
        up = forward = None
        source = "landmarks"
    try:
        est_up, est_forward = landmark_frame(raw, vertices)
    except LandmarkError:
        if up is None:   # too few landmarks to tell: faceforge's frame, and the landmark checks say what is missing
            up, forward, source = np.array([0.0, 1.0, 0.0]), np.array([0.0, 0.0, 1.0]), "default"
        return HeadOrientation(frame_rotation(up, forward), axis_name(up), axis_name(forward), source, float("nan"))
    if up is None:
        try:
            up, forward = snap_to_axes(est_up, est_forward)
        except ValueError as exc:
            raise LandmarkError(f"{exc} (fit.orientation=UP,FORWARD, or orientation: {{up, forward}} "
                                "in the landmark file)", raw.path) from None
    tilt = max(angle_between(up, est_up), angle_between(forward, est_forward))
    if tilt > MAX_ORIENTATION_TILT_DEG:
        raise LandmarkError(f"the {source} say{'s' if source != 'landmarks' else ''} the head is "
                            f"{axis_name(up)} up facing {axis_name(forward)}, but its landmarks rise along "
                            f"{np.round(est_up, 2).tolist()} and face {np.round(est_forward, 2).tolist()} "
                            f"({tilt:.0f} degrees apart)", raw.path)
    rotation = frame_rotation(up, forward)
    if source == "landmarks" and reference is not None and straighten_deg is not None:
        off = max(angle_between(rotation @ est_up, reference[0]), angle_between(rotation @ est_forward, reference[1]))
        if off > straighten_deg:
            from faceforge.geometry.orientation import straightening_rotation

            return HeadOrientation(straightening_rotation(est_up, est_forward, *reference), axis_name(up),
                                   axis_name(forward), source, tilt, straightened_deg=off)
    return HeadOrientation(rotation, axis_name(up), axis_name(forward), source, tilt)
