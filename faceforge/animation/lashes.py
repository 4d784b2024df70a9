"""Lash cards ride their lids (beyond the paper; the lids are kinematic, :mod:`faceforge.animation.eyelids`).

A game or film head often carries its eyelashes as separate cards along the lid margins. The lid
field moves only the lid's own skin (an eyeball or a card in the same mesh is another piece), so a
closing lid left its lashes standing in front of the eye. :func:`lash_carriers` finds the cards and
the lid vertex each of their vertices rides: :class:`~faceforge.animation.eyelids.Eyelids` adds that
vertex's move (everything the lids did to it in the frame) to the lash vertex. A card translates
with the margin; it does not turn with the lid's curve.
"""

from __future__ import annotations

import numpy as np

#: a piece of the mesh other than the lid's own that comes this close to a lid's skin (in half the
#: eye's corner distance) and is no larger than the eye (its extent in the same unit) is its lashes
LASH_TOUCH, LASH_SIZE = 0.1, 2.0


def lash_carriers(rest: np.ndarray, piece: np.ndarray, rigid: np.ndarray, fields) -> tuple[np.ndarray, np.ndarray]:
    """(lash vertices (k,), lid vertices (k,)): the vertices of the lash cards of the eyes of
    ``fields`` (:class:`LidField`, their ``index`` the lid's own skin) and, for each, the lid
    vertex it rides (its nearest): a lash card is a piece other than the lid's, not rigid (an
    eyeball), within :data:`LASH_TOUCH` of the lid's skin and no larger than :data:`LASH_SIZE`
    (both in half the eye's corner distance), its centroid not in the middle half of the eye's
    opening (an iris disc, as MediaPipe's, is not a lash). rest (n, 3); piece (n,) component labels (-1: no
    face); rigid (n,) bool."""
    from scipy.spatial import cKDTree

    lash, lid = [], []
    for field in fields:
        if not len(field.index):
            continue
        half = field.eye.half
        own = np.unique(piece[field.index])
        tree = cKDTree(rest[field.index])
        near = np.flatnonzero(tree.query(rest, distance_upper_bound=LASH_TOUCH * half)[0] < np.inf)
        for k in np.unique(piece[near]):
            if k < 0 or k in own:
                continue
            ids = np.flatnonzero((piece == k) & ~rigid)
            if not len(ids) or np.ptp(rest[ids], axis=0).max() > LASH_SIZE * half:
                continue
            height = (rest[ids].mean(axis=0) - field.eye.centre) @ field.eye.axes[1]
            if 0.5 * field.eye.lower < height < 0.5 * field.eye.upper:
                continue                                   # in the opening: an iris, a cornea
            lash.append(ids)
            lid.append(field.index[tree.query(rest[ids])[1]])
    if not lash:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    return np.concatenate(lash), np.concatenate(lid)
