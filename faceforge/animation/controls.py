"""FAPs to controls (paper §9): a FAP track's frames -> contractions and jaw DOFs.

The track's low-level FAPs (its own values plus those of its FAP 2 expressions and FAP 1
visemes, :func:`track_faps`) go through the mapping
(:func:`faceforge.animation.fap_mapping.fap_controls`) to contractions in the order of the
rig's controls (:attr:`faceforge.animation.rig.BoundHead.controls`) and jaw DOFs.
"""

from __future__ import annotations


def track_faps(track, mapping):
    """``(faps, missing)``: the low-level FAP frames ``(F, 68)`` of a track, its own values
    (absent ones 0) plus those of its FAP 2 expressions and FAP 1 visemes (the mapping's
    ``expressions`` and ``visemes`` tables), and the names of the visemes it selects that the
    mapping has no shape for."""
    import numpy as np

    from faceforge.animation.fap_mapping import expression_faps, viseme_faps

    faps = np.nan_to_num(np.asarray(track.values, dtype=float))
    faps[:, :2] = 0.0
    shapes, missing = viseme_faps(mapping, track.viseme)
    return faps + expression_faps(mapping, track.expression) + shapes, missing


def track_controls(track, mapping, head):
    """(contractions (F, m), jaw (F, 3), unmapped FAP numbers with nonzero values, the track's
    low-level FAP frames (F, 68) of :func:`track_faps`). FAP 1 counts as unmapped when the
    track selects a viseme the mapping's ``visemes`` table lacks."""
    import numpy as np

    faps, missing = track_faps(track, mapping)
    mapped = set(mapping.mapped_faps().tolist())
    unmapped = sorted(int(k + 1) for k in np.flatnonzero(np.abs(faps).max(axis=0) > 0) if k + 1 not in mapped)
    if missing:
        unmapped = [1, *unmapped]
    c, jaw = controls(mapping, faps, head)
    return c, jaw, unmapped, faps


def visemes_played(track) -> tuple[list[str], int]:
    """The names (in code order) of the visemes a track's FAP 1 gives a weight, and in how
    many frames it gives one."""
    from faceforge.animation.fap_mapping import viseme_weights
    from faceforge.mpeg4.visemes import VISEME_CODES

    w = viseme_weights(track.viseme) > 0.0
    names = [name for name in sorted(VISEME_CODES, key=VISEME_CODES.get) if w[:, VISEME_CODES[name] - 1].any()]
    return names, int(w.any(axis=1).sum())


def controls(mapping, faps, head):
    """Contractions in ``head.controls`` order (F, m) and jaw DOFs (F, 3) for FAPs (F, 68).

    With muscles, every muscle the mapping names must exist (TemplateError otherwise);
    without (a jaw-only head), the muscle part is dropped.
    """
    import numpy as np

    from faceforge.animation.fap_mapping import fap_controls

    names = head.controls if head.controls else mapping.muscles
    c, jaw = fap_controls(mapping, faps, names, head.fapu.as_dict(), head.levers)
    return (c if head.controls else np.zeros((len(c), 0))), jaw
