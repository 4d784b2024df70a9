"""The sphincter muscle's contraction (§5.2.2): the orifice closes along the fitted ellipse.

Sphincter contraction (§5.2.2). The paper's
``delta = (o - s1) (1 - c) cos(pi/2 (1 - sqrt(y^2 b^2 + x^2 a^2) / (ab)))``
moves every sample to the centre at c = 0, contradicting "c = 0 is rest". We
read ``(1 - c)`` as the *remaining* fraction of the orifice and use
``delta = c kappa P (o - s1) cos(pi/2 (1 - r))``: c = 0 is the rest state and c = 1
the maximal contraction, which moves each inner sample the fraction ``kappa``
(``max_contraction``, default :data:`SPHINCTER_MAX_CONTRACTION` = 0.5) of the
way to the centre, times the fall-off. kappa = 1 (a fully closed orifice)
collapses the inner loop to a point; its wall triangles degenerate and the
dihedral bending projection diverges (observed from kappa c ~ 0.6 on the
synthetic mouth), so the default stops half way (a puckered mouth). ``P`` projects onto
the ellipse's plane (dir_a, dir_b): the loops wrap around the face, so their mean ``o`` lies
behind the lips, and the literal ``o - s1`` pulled the lips into the head (on the MakeHuman
head the lower lip went down and back at c = 1 instead of up); the paper's ellipse is planar
and its (x, y) are in-plane coordinates, so the contraction is taken in that plane. ``r`` is the ellipse
radius of the outer sample ``s3 = o + x dir_a + y dir_b``, written correctly as
``r = sqrt(x^2 / a^2 + y^2 / b^2) = sqrt(x^2 b^2 + y^2 a^2) / (ab)`` (the paper
swaps a and b, which would give r != 1 on the ellipse itself), clipped so that
``|1 - r| <= 1``. The ellipse is fitted by linear least squares
(``q11 x^2 + 2 q12 x y + q22 y^2 = 1`` about the centre ``o`` = mean of all
inner and outer samples) in the plane of best fit (PCA) of those samples,
recomputed every frame from the current, uncontracted samples. The same delta
moves the pair's inner and outer samples (with a protrusion drive it also has a part along
the plane's normal: :func:`build_sphincter_muscle`, ``protrusion``); the interior (``0 < j < w-1``)
bottom particles are not bound, as in the linear muscle. With material sampling the
per-frame targets are compiled (:func:`_sphincter_grid`: the plane from the eigenvectors of
the 3 x 3 scatter matrix, the conic by Gram-Schmidt); :meth:`Muscle._grid_targets` is its
numpy twin, equal to round-off.
"""

from __future__ import annotations

import numba
import numpy as np

from faceforge.constants import FLOAT, NUMBA_OPTIONS


def fit_ellipse(points) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, float]:
    """Least-squares ellipse of ``points (k, 3)`` in their plane of best fit.

    Returns ``(o (3,), dir_a (3,), dir_b (3,), a, b)``: centre (the mean, as
    §5.2.2 prescribes), unit semi-major / semi-minor directions and semi-axis
    lengths (a >= b > 0). The conic ``q11 x^2 + 2 q12 xy + q22 y^2 = 1`` about
    ``o`` is solved by linear least squares; if it is not positive definite
    (nearly collinear points) the PCA standard deviations scaled by sqrt(2)
    are used instead.
    """
    p = np.asarray(points, dtype=FLOAT)
    o = p.mean(axis=0)
    d = p - o
    _, sv, vt = np.linalg.svd(d, full_matrices=False)
    e1, e2 = vt[0], vt[1]
    x, y = d @ e1, d @ e2
    A = np.stack([x * x, 2 * x * y, y * y], 1)
    q, *_ = np.linalg.lstsq(A, np.ones(len(p)), rcond=None)
    Q = np.array([[q[0], q[1]], [q[1], q[2]]])
    lam, vec = np.linalg.eigh(Q)
    if lam[0] > 0:
        a, b = 1.0 / np.sqrt(lam[0]), 1.0 / np.sqrt(lam[1])
        ua, ub = vec[:, 0], vec[:, 1]
    else:
        n = max(len(p), 1)
        a, b = sv[0] * np.sqrt(2.0 / n), max(sv[1] * np.sqrt(2.0 / n), 1e-300)
        ua, ub = np.array([1.0, 0.0]), np.array([0.0, 1.0])
    dir_a = ua[0] * e1 + ua[1] * e2
    dir_b = ub[0] * e1 + ub[1] * e2
    return o, dir_a, dir_b, float(a), float(b)


@numba.njit(**NUMBA_OPTIONS)
def _loop_samples(p, seg, t, out, col):  # pragma: no cover - numba
    """``eval_polyline(p, None, seg, t, closed=True)`` into ``out[:, col]`` (``out (h, w, 3)``)."""
    m = p.shape[0]
    for i in range(seg.shape[0]):
        a = seg[i]
        b = a + 1 if a + 1 < m else 0
        for d in range(3):
            out[i, col, d] = (1.0 - t[i]) * p[a, d] + t[i] * p[b, d]


@numba.njit(**NUMBA_OPTIONS)
def _conic_lstsq(x, y):  # pragma: no cover - numba
    """Least-squares ``q (3,)`` of ``q0 x^2 + 2 q1 x y + q2 y^2 = 1`` over the points ``x, y
    (k,)``: modified Gram-Schmidt on the columns and the right-hand side together (backward
    stable, as ``np.linalg.lstsq`` for a full-rank system)."""
    k = x.shape[0]
    m = np.empty((4, k))
    for i in range(k):
        m[0, i] = x[i] * x[i]
        m[1, i] = 2.0 * x[i] * y[i]
        m[2, i] = y[i] * y[i]
        m[3, i] = 1.0
    r = np.zeros((3, 4))
    for j in range(3):
        r[j, j] = np.sqrt(np.sum(m[j] * m[j]))
        m[j] /= r[j, j]
        for l in range(j + 1, 4):
            r[j, l] = np.sum(m[j] * m[l])
            m[l] -= r[j, l] * m[j]
    q = np.empty(3)
    for j in range(2, -1, -1):
        acc = r[j, 3]
        for l in range(j + 1, 3):
            acc -= r[j, l] * q[l]
        q[j] = acc / r[j, j]
    return q


@numba.njit(**NUMBA_OPTIONS)
def _sphincter_grid(p1, seg1, t1, p3, seg3, t3, c, grid, r1, r3, carry, lift, fwd, low=0.0, centre=0.0,
                    vert=1.0, evup=False, bulge=0.0):  # pragma: no cover - numba
    """Compiled twin of the material-sampling sphincter branch of :meth:`Muscle._grid_targets`:
    fills the columns 0 (A1) and ``w - 1`` (A3) of ``grid (h, w, 3)`` with the loops' samples
    at ``(seg, t)`` of the closed polylines ``p1 (p, 3)``, ``p3 (q, 3)``, moved by
    :func:`sphincter_displacement` with ``c`` (already times the maximal closure) and ``lift``
    (``fwd (3,)``: :attr:`Muscle.forward`) when either is > 0; before that, with ``carry
    (h,)`` (:attr:`Muscle.carry_inner`, empty: none), each inner sample gets ``carry[i] ((s3 -
    r3) - (s1 - r1))``, ``r1, r3 (h, 3)`` the rest samples; ``low``: the lower part's raise
    (:func:`lower_raise`, already times the maximal closure); ``centre``: where the closure pulls
    (:attr:`Muscle.closure_centre`); ``vert``, ``evup``: the closure's vertical share and the
    eversion along the plane's up direction (:attr:`Muscle.closure_vertical`,
    :attr:`Muscle.eversion_up`); ``bulge``: the lips' forward bulge per unit of their closure's
    length (:attr:`Muscle.bulge`). Same values as the numpy code to round-off (LAPACK's,
    summation order).

    Length: one compiled kernel (ellipse fit and the per-sample displacement in one pass); kept
    whole for speed.
    """
    h = grid.shape[0]
    w1 = grid.shape[1] - 1
    _loop_samples(p1, seg1, t1, grid, 0)
    _loop_samples(p3, seg3, t3, grid, w1)
    if carry.shape[0]:   # the inner loop follows the outer one's drag (see Muscle.carry_inner)
        for i in range(h):
            for j in range(3):
                grid[i, 0, j] += carry[i] * ((grid[i, w1, j] - r3[i, j]) - (grid[i, 0, j] - r1[i, j]))
    if not (c > 0.0 or lift > 0.0 or low > 0.0):
        return
    # fit_ellipse of the 2h samples (inner then outer)
    k = 2 * h
    d = np.empty((k, 3))
    for i in range(h):
        for j in range(3):
            d[i, j] = grid[i, 0, j]
            d[h + i, j] = grid[i, w1, j]
    o = np.empty(3)
    for j in range(3):
        o[j] = np.mean(d[:, j])
    for i in range(k):
        for j in range(3):
            d[i, j] -= o[j]
    # the plane of best fit: the right singular vectors of d are the eigenvectors of d^T d
    gram = d.T @ d
    ev, evec = np.linalg.eigh(gram)                  # ascending
    e1 = evec[:, 2].copy()
    e2 = evec[:, 1].copy()
    sv0 = np.sqrt(max(ev[2], 0.0))
    sv1 = np.sqrt(max(ev[1], 0.0))
    x = d @ e1
    y = d @ e2
    q = _conic_lstsq(x, y)
    lam = np.full(2, -1.0)      # no conic (collinear samples: q is not finite): the PCA fallback
    vec = np.eye(2)
    if np.all(np.isfinite(q)):
        Q = np.empty((2, 2))
        Q[0, 0] = q[0]
        Q[0, 1] = q[1]
        Q[1, 0] = q[1]
        Q[1, 1] = q[2]
        lam, vec = np.linalg.eigh(Q)
    if lam[0] > 0:
        a, b = 1.0 / np.sqrt(lam[0]), 1.0 / np.sqrt(lam[1])
        ua0, ua1, ub0, ub1 = vec[0, 0], vec[1, 0], vec[0, 1], vec[1, 1]
    else:
        a, b = sv0 * np.sqrt(2.0 / k), max(sv1 * np.sqrt(2.0 / k), 1e-300)
        ua0, ua1, ub0, ub1 = 1.0, 0.0, 0.0, 1.0
    da = ua0 * e1 + ua1 * e2
    db = ub0 * e1 + ub1 * e2
    # sphincter_displacement: delta = (c P (o - s1) + lift (b n + EVERSION y db)) cos(pi/2 (1 - r)),
    # r and y of the outer sample, n the plane's normal on the side of fwd
    nrm = np.empty(3)
    nrm[0] = da[1] * db[2] - da[2] * db[1]
    nrm[1] = da[2] * db[0] - da[0] * db[2]
    nrm[2] = da[0] * db[1] - da[1] * db[0]
    if nrm[0] * fwd[0] + nrm[1] * fwd[1] + nrm[2] * fwd[2] < 0.0:
        for j in range(3):
            nrm[j] = -nrm[j]
    lift = lift * b
    # the lower part's raise: along u, the plane's direction nearest +Y (up), by the ellipse's
    # radius ru along it (lower_raise)
    ua = da[1]
    ub = db[1]
    un = np.sqrt(ua * ua + ub * ub)
    ru = 0.0
    if un > 1e-12:
        ua /= un
        ub /= un
        if low > 0.0:
            ru = 1.0 / np.sqrt(ua * ua / (a * a) + ub * ub / (b * b))
    else:              # no up direction in the plane: the paper's isotropic closure, eversion along db
        vert = 1.0
        evup = False
    flat = 1.0 - vert  # the share of the closure along u that is taken away (closure_vertical)
    if not ru > 0.0:   # no raise asked, or no up direction in the plane (a degenerate ellipse)
        low = 0.0
        ru = 1.0
    low = low * ru
    cen = np.empty(3)      # the closure's centre: o moved `centre` of the way to the inner loop's mean
    for j in range(3):
        cen[j] = o[j] + centre * np.mean(d[:h, j])
    for i in range(h):
        xo = 0.0
        yo = 0.0
        ta = 0.0
        tb = 0.0
        for j in range(3):
            xo += (grid[i, w1, j] - o[j]) * da[j]
            yo += (grid[i, w1, j] - o[j]) * db[j]
            ta += (cen[j] - grid[i, 0, j]) * da[j]
            tb += (cen[j] - grid[i, 0, j]) * db[j]
        r = np.sqrt(xo * xo * b * b + yo * yo * a * a) / (a * b)
        fall = np.cos(0.5 * np.pi * min(max(1.0 - r, -1.0), 1.0))
        wl = low * min(max(-(xo * ua + yo * ub) / ru, 0.0), 1.0) if low > 0.0 else 0.0   # lower_weights
        tu = flat * (ta * ua + tb * ub)      # closure_vertical: less of the pull along u
        ta -= tu * ua
        tb -= tu * ub
        bl = bulge * c * np.sqrt(ta * ta + tb * tb)   # the bulge: forward by the closure's length
        yu = xo * ua + yo * ub               # the outer sample's height along u
        for j in range(3):
            ev = yu * (ua * da[j] + ub * db[j]) if evup else yo * db[j]
            dj = (c * (ta * da[j] + tb * db[j]) + lift * (nrm[j] + EVERSION * ev / b) + bl * nrm[j]
                  + wl * (ua * da[j] + ub * db[j] - LOWER_INWARD * nrm[j])) * fall
            grid[i, 0, j] += dj
            grid[i, w1, j] += dj


#: suffix of a sphincter's protrusion control (:func:`protrusion_control`)
PROTRUSION_SUFFIX = ".protrude"


def protrusion_control(name: str) -> str:
    """The control name of sphincter ``name``'s protrusion drive (``orbicularis_oris.protrude``):
    a contraction-like value in [0, 1] that FAP mappings and ``MusculoskeletalSystem.step`` take
    alongside the muscles' own (:attr:`Muscle.protrusion`)."""
    return name + PROTRUSION_SUFFIX


#: the protrusion drive from which a sphincter's closure keeps the ring's height in full
#: (:func:`vertical_share`): the bake's pucker solved to a drive of 0.36-0.5 with the closure at 1,
#: and a share proportional to the drive left half of the upper lip's fall (MakeHuman: 8.1 1.9 mm down)
VERTICAL_RAMP = 0.25


def vertical_share(closure_vertical: float, protrude: float, active: bool) -> float:
    """The closure's share along the loops' plane's up direction for :func:`sphincter_displacement`
    (``vertical``) / the compiled targets: ``1 - (1 - closure_vertical) p``, ``p`` the protrusion
    drive over :data:`VERTICAL_RAMP`, clipped to [0, 1] (0 when passive; :attr:`Muscle.closure_vertical`).

    Anatomy: the closure alone is the lips pressed together (AU23/24; the upper lip lowered, FAP
    4/51), the paper's isotropic closure; with the lips pushed out (the pars peripheralis, a
    pucker or a rounded viseme) the ring shortens along its fibres round the mouth: on a wide,
    flat mouth the corners come in while the lips, held behind by the teeth, go forward, and the
    ring's height barely shrinks. The paper's closure toward the loops' mean, which lies below the
    mouth where the outer loop reaches the chin, pulled the upper lip 5-7 mm down in a pucker
    (docs/notes/pucker16.md); taken always, the lowered upper lip of FAP 4/51 was lost."""
    return 1.0 - (1.0 - float(closure_vertical)) * protrusion_ramp(protrude, active)


def protrusion_ramp(protrude: float, active: bool) -> float:
    """``p`` in [0, 1]: the protrusion drive over :data:`VERTICAL_RAMP`, clipped (0 when passive):
    how far :func:`vertical_share` and :func:`bulge_share` have turned from the paper's closure."""
    return float(np.clip(protrude / VERTICAL_RAMP, 0.0, 1.0)) if active else 0.0


def bulge_share(bulge: float, protrude: float, active: bool) -> float:
    """The bulge for :func:`sphincter_displacement` / the compiled targets: ``bulge``
    (:attr:`Muscle.bulge`) times the protrusion drive over :data:`VERTICAL_RAMP`, clipped to
    [0, 1] (0 when passive): as :func:`vertical_share`, the closure alone (the lips pressed, the
    upper lip lowered: FAP 4/51, AU23/24) stays the paper's, bit for bit; a ring that closes while
    it pushes its lips out (a pucker, the rounded visemes) bulges them forward off the teeth.
    Taken for every closure, the bulge moved the lowered upper lip forward and cost MakeHuman's
    calibrated ``lower_t_midlip`` rows (9-11 -> 19-20 %, docs/notes/purse19.md)."""
    return float(bulge) * protrusion_ramp(protrude, active) if bulge else 0.0


#: suffix of a sphincter's lower-part control (:func:`lower_control`)
LOWER_SUFFIX = ".lower"


def lower_control(name: str) -> str:
    """The control name of sphincter ``name``'s lower part (``orbicularis_oris.lower``): a
    contraction-like value in [0, 1] that raises the lower half of the loops toward the upper
    one (:func:`lower_raise`)."""
    return name + LOWER_SUFFIX


def lower_weights(y, r: float) -> np.ndarray:
    """``(h,)`` share of the lower part's raise per sample pair: ``clip(-y / r, 0, 1)``, ``y (h,)``
    the outer sample's height over the ellipse's centre along ``u``, the direction in the
    ellipse's plane nearest +Y (up, the frame's convention), ``r`` the ellipse's radius along
    ``u``: about 1 at the lower lip's middle, 0 along the upper lip and little at the corners.
    Not the samples' index (a symmetric rig restarts the loops at the midline,
    muscles.mirror.symmetric_loop), nor the minor axis (on the MediaPipe mask the loops' fitted
    ellipse is taller than wide: its minor axis runs across the mouth)."""
    return np.clip(-np.asarray(y, FLOAT) / r, 0.0, 1.0)


#: how far a full lower-part drive raises the lower lip's middle, in the ellipse's semi-minor
#: axes times the maximal closure (:func:`lower_raise`)
LOWER_RAISE = 1.0
#: how far it moves the lower lip in (toward the teeth, against :attr:`Muscle.forward`) per unit
#: of its raise: a lip press rolls the lips in (the MakeHuman unit mouth-compression: FDP 8.2
#: up 97 MNS and back 134, 2.3 up 70 and back 11); raised in the loops' plane alone, whose
#: normal tilts down with the chin, the lower lip went up and forward (MakeHuman, drive 0.5: FDP
#: 2.3 up 125 MNS, forward 30) in front of the upper lip, its edge cutting through it
LOWER_INWARD = 0.5


def lower_raise(drive: float, active: bool, max_contraction: float) -> float:
    """The lower part's raise for :func:`sphincter_displacement` / the compiled targets: ``drive``
    clipped to [0, 1] (0 when passive) times :data:`LOWER_RAISE` and ``max_contraction``.

    Anatomy: the lower lip is raised by the orbicularis oris' lower part (pars marginalis of
    the lower lip: lips pressed together, AU24; the lower lip rolled in, AU28) and pushed up by
    the mentalis below it (AU17). The paper's sphincter closes toward the loops' mean, which on
    a face whose outer loop reaches the chin lies below the lower lip (the whole-ring
    contraction lowered it on ICT), so the lower part has its own drive: every lower sample pair
    moves ``low r w_i`` along ``u``, the ellipse plane's direction nearest +Y (``r`` the
    ellipse's radius along ``u``, ``w_i`` :func:`lower_weights`), and :data:`LOWER_INWARD` times
    that against the plane's forward normal, with the contraction's fall-off."""
    return float(np.clip(drive, 0.0, 1.0)) * LOWER_RAISE * max_contraction if active else 0.0


#: how far a protruding sphincter turns its lips out (away from the centre along the ellipse's
#: minor axis: the upper lip up, the lower lip down; 0 at the corners), per unit of its forward
#: push, times the outer sample's height over the semi-minor axis (:func:`sphincter_displacement`).
#: Along the plane's normal alone the push tilted with the plane (the loops wrap round a face whose
#: chin lies back), and the upper lip went down as it went forward (MakeHuman, drive 0.5: FDP 8.1
#: 0.5 mm down, 1.8 mm forward), where a real pucker turns it up and out (the MakeHuman units:
#: mouth-protusion 8.1 5 mm up and 5 forward, 8.2 11 down and 5 forward; mouth-pursing 8.1 2 up,
#: 7 forward, 8.2 4 down, 5 forward).
EVERSION = 1.0
#: fraction of the way to the centre that c = 1 moves the sphincter's inner loop
SPHINCTER_MAX_CONTRACTION = 0.5
#: fraction of the fibre length that c = 1 removes from a linear muscle
def sphincter_displacement(inner, outer, c: float, lift: float = 0.0, forward=None,
                           low: float = 0.0, centre: float = 0.0, vertical: float = 1.0,
                           eversion_up: bool = False, bulge: float = 0.0) -> np.ndarray:
    """Displacement ``delta (h, 3)`` of each inner/outer sample pair (§5.2.2, see module doc).

    ``inner, outer : (h, 3)`` the current samples of A1 and A3; ``c`` already
    multiplied by the maximal closure. ``delta = (c P (o - s1) + lift (b n + EVERSION y
    dir_b)) cos(pi/2 (1 - r))``, ``P`` the projection onto the ellipse's plane, ``b`` its
    semi-minor axis, ``y`` the outer sample's coordinate along it (:data:`EVERSION`) and ``n``
    its unit normal on the side of ``forward (3,)`` (:attr:`Muscle.forward`; needed when
    ``lift`` is not 0). ``lift``: the protrusion drive times :attr:`Muscle.protrusion` and the
    maximal closure. ``low``: the lower part's raise (:func:`lower_raise`): ``low r w_i`` up
    along the plane (:func:`lower_weights`) and :data:`LOWER_INWARD` times that inward
    (``forward`` needed). ``centre`` in [0, 1] (:attr:`Muscle.closure_centre`): the closure pulls
    toward ``o + centre (mean(inner) - o)`` instead of the ellipse's centre ``o`` (0, the paper).
    ``vertical`` in [0, 1] (:attr:`Muscle.closure_vertical`): the closure's part along ``u``, the
    plane's direction nearest +Y, is scaled by it (1, the paper: isotropic; 0: the ring narrows, its
    height stays); ``eversion_up`` (:attr:`Muscle.eversion_up`): the eversion is taken along ``u``
    by the outer sample's height along ``u`` instead of along ``dir_b`` (the same on a mouth whose
    minor axis is vertical; on one whose fitted ellipse is taller than wide ``dir_b`` runs across
    it and the eversion spread the corners). Without an up direction in the plane both are off.
    ``bulge`` >= 0 (:attr:`Muscle.bulge`; 0, the paper): each pair also moves ``bulge`` times the
    length of its own closure (the in-plane part above, mesh units) along ``n`` (``forward``
    needed): the ring, shortening round the teeth, thickens and pushes the lips forward off them.
    """
    s1 = np.asarray(inner, dtype=FLOAT)
    s3 = np.asarray(outer, dtype=FLOAT)
    o, da, db, a, b = fit_ellipse(np.concatenate([s1, s3]))
    x = (s3 - o) @ da
    y = (s3 - o) @ db
    r = np.sqrt(x * x * b * b + y * y * a * a) / (a * b)
    fall = np.cos(0.5 * np.pi * np.clip(1.0 - r, -1.0, 1.0))
    to = o + float(centre) * (s1.mean(axis=0) - o) - s1
    un = np.hypot(da[1], db[1])
    up = (da[1] * da + db[1] * db) / un if un > 1e-12 else None    # u: the plane's direction nearest +Y
    if up is not None and vertical != 1.0:
        to = to - (1.0 - float(vertical)) * np.outer(to @ up, up)      # closure_vertical
    d = float(c) * (np.outer(to @ da, da) + np.outer(to @ db, db))      # in the ellipse's plane
    if lift or low or (bulge and c):               # the plane's normal on the side of forward
        n = np.cross(da, db)
        if n @ np.asarray(forward, dtype=FLOAT) < 0.0:
            n = -n
    if bulge and c:                                # forward by the closure's own length
        d = d + float(bulge) * np.outer(np.linalg.norm(d, axis=1), n)
    if lift:                                       # forward, and the lips turned out
        ev = np.outer((s3 - o) @ up, up) if eversion_up and up is not None else np.outer(y, db)
        d = d + lift * (b * n + EVERSION * ev)
    if low and up is not None:      # ru: the ellipse's radius along u
        ua, ub = da[1] / un, db[1] / un
        ru = 1.0 / np.sqrt(ua * ua / (a * a) + ub * ub / (b * b))
        d = d + (low * ru) * np.outer(lower_weights(x * ua + y * ub, ru), up - LOWER_INWARD * n)
    return d * fall[:, None]


def align_loops(inner, outer) -> tuple[np.ndarray, np.ndarray]:
    """Reorder the closed point loop ``outer (q, 3)`` to match ``inner (p, 3)``.

    Makes both loops turn the same way about their common mean (in the plane of
    best fit) and rotates ``outer`` to start at its point nearest ``inner[0]``.
    """
    p = np.asarray(inner, FLOAT)
    q = np.asarray(outer, FLOAT)
    o = np.concatenate([p, q]).mean(axis=0)
    _, _, vt = np.linalg.svd(np.concatenate([p, q]) - o, full_matrices=False)
    n = vt[2]

    def turn(loop):
        d = loop - o
        return np.sum(np.cross(d, np.roll(d, -1, axis=0)) @ n)

    if np.sign(turn(p)) != np.sign(turn(q)):
        q = q[::-1]
    start = int(np.argmin(np.linalg.norm(q - p[0], axis=1)))
    return p, np.roll(q, -start, axis=0)
