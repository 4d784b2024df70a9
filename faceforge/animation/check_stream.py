"""The animation checks of :func:`faceforge.animation.checks.check_animation`, a chunk at a time.

A long take is never held whole (issue 28): :class:`StreamChecker` takes the frames in
order, in chunks of any size, keeps per-frame figures (a few numbers a frame) and copies of
the few frames the skull test looks at, and gives the same
:class:`~faceforge.animation.checks.FrameReport` as ``check_animation`` on all frames at
once (the tests compare the two).
"""

from __future__ import annotations

import numpy as np

from faceforge.animation.checks import (FrameReport, _thrown, _where, displacement_limit, fold_limit, folded_edges,
                                        inside_skull, inverted_faces)


class StreamChecker:
    """Checks of an animation of ``n_frames`` frames fed in order with :meth:`add`.

    rest (n, 3), faces (m, 3) of the skin; ``sample``, ``tolerance``: as for
    :func:`~faceforge.animation.checks.check_animation`; ``inside_at_rest`` (n,) bool or None: the
    vertices the bone check does not count, as there (a bound head's
    :meth:`~faceforge.animation.rig.BoundHead.inside_at_rest`: also its rigid pieces).
    """

    def __init__(self, rest: np.ndarray, faces: np.ndarray, n_frames: int, sample: int = 8,
                 tolerance: float | None = None, inside_at_rest: np.ndarray | None = None):
        self.inside_at_rest = inside_at_rest
        self.rest = np.asarray(rest, dtype=float)
        self.faces = np.asarray(faces, dtype=np.int64)
        self.n_frames = int(n_frames)
        self.tolerance = (1e-3 * float(np.linalg.norm(np.ptp(self.rest, axis=0)))
                          if tolerance is None else tolerance)
        self.sampled = set(np.linspace(0, self.n_frames - 1, min(sample, self.n_frames)).astype(int).tolist()) \
            if self.n_frames else set()
        self.kept: dict[int, np.ndarray] = {}
        self.seen = 0
        self.non_finite = 0
        self.disp = np.zeros(self.n_frames)
        self.worst = -1
        self.worst_frame = None
        self.inverted_total = 0
        self.inverted_max = 0
        self.inverted_any = np.zeros(len(self.faces), bool)
        self.folded_any = None
        self.folded_max = 0
        self.n_edges = 0
        self.where: dict = {}
        #: a :class:`~faceforge.animation.checks.CarriedInversions` fed by the caller, or None
        self.carried = None

    def add(self, frames: np.ndarray) -> None:
        """The next ``frames (k, n, 3)`` of the animation (copied where kept)."""
        frames = np.asarray(frames, dtype=float)
        k, start = len(frames), self.seen
        if start + k > self.n_frames:
            raise ValueError(f"more than the {self.n_frames} frames announced")
        finite = np.isfinite(frames).all(axis=(1, 2))
        self.non_finite += int(np.count_nonzero(~finite))
        clean = np.nan_to_num(frames)
        disp = np.linalg.norm(clean - self.rest, axis=2).max(axis=1)
        self.disp[start:start + k] = disp
        for j in range(k):
            if self.worst < 0 or disp[j] > self.disp[self.worst]:   # np.argmax: the first of the largest
                self.worst, self.worst_frame = start + j, frames[j].copy()
            if start + j in self.sampled:
                self.kept[start + j] = frames[j].copy()
        flips = inverted_faces(self.rest, clean, self.faces)
        inv = flips.sum(axis=1)
        self.inverted_total += int(inv.sum())
        self.inverted_max = max(self.inverted_max, int(inv.max()) if len(inv) else 0)
        self.inverted_any |= flips.any(axis=0)
        folds = folded_edges(self.rest, clean, self.faces)
        self.n_edges = folds.shape[1]
        self.folded_any = folds.any(axis=0) if self.folded_any is None else self.folded_any | folds.any(axis=0)
        self.folded_max = max(self.folded_max, int(folds.sum(axis=1).max()) if len(folds) else 0)
        found = _where(finite, inv, folds.sum(axis=1), start)
        for name, value in found.items():   # the first frame, or the most folded (the first of them)
            if name not in self.where or (name == "folded" and value[1] > self.where[name][1]):
                self.where[name] = value
        self.seen += k

    def report(self, skull=None) -> FrameReport:
        """The :class:`FrameReport` of the frames added (all ``n_frames`` of them); ``skull``:
        ``frame_index -> [(vertices, faces)]`` as for ``check_animation``."""
        if self.seen != self.n_frames:
            raise ValueError(f"{self.seen} frames added, {self.n_frames} announced")
        where, inside = _thrown(self.where, self.disp, self.rest), {}
        if skull is not None and self.n_frames:
            frames = dict(self.kept)
            frames[self.worst] = self.worst_frame
            inside = inside_skull(self.rest, frames, sorted(self.sampled | {self.worst}), skull, self.tolerance,
                                  self.inside_at_rest)
            if inside:
                where["inside_skull"] = inside
        inside_total = sum(inside.values())
        if self.folded_any is None:   # no frame: the edge count from an empty pass
            self.n_edges = folded_edges(self.rest, np.zeros((0,) + self.rest.shape), self.faces).shape[1]
        return FrameReport(frames=self.n_frames, non_finite=self.non_finite,
                           inverted_triangles=self.inverted_total, skin_inside_skull=inside_total,
                           max_displacement=float(self.disp.max()) if self.n_frames else 0.0,
                           worst_frame=self.worst,
                           inverted_faces=int(self.inverted_any.sum()),
                           inverted_max_per_frame=self.inverted_max,
                           folded_edges=int(self.folded_any.sum()) if self.folded_any is not None else 0,
                           folded_max_per_frame=self.folded_max,
                           fold_limit=fold_limit(self.n_edges), where=where,
                           displacement_limit=displacement_limit(self.rest),
                           carried=None if self.carried is None else self.carried.as_dict())
