"""Kinematic eyelids for the MPEG-4 eyelid FAPs 19-22 (close_t_l/r_eyelid, close_b_l/r_eyelid).

The paper's muscle map has no eyelid muscle, and none of the sample heads has an eyeball to
slide a lid over, so the lids are not simulated: their motion is a displacement field laid
over the simulated skin, like a blend shape, built for each eye from its four FDPs.

**The eye's frame.** The eye corners (outer, inner) and the lid FDPs (upper, lower) of the
neutral face: ``u`` along the corners towards the subject's left (+X), ``v`` up, ``w``
forward; origin at the corners' midpoint. ``half`` is half the corner distance, ``upper``
and ``lower`` the lid FDPs' heights (``upper > 0 > lower``); the lid opening ``gap`` is
their difference (IRISD0 when both eyes are alike).

**The margins.** Each lid margin is taken as a curve through both corners and its lid FDP:
heights ``top * s(u)`` and ``bottom * s(u)``, depth ``lid_depth * s(u)``, with the taper
``s(u) = 1 - |(u - peak) / (half -+ peak)|^TAPER``: 1 at ``peak``, the lid FDPs' mean ``u``,
0 at and beyond the corners (:data:`TAPER` 3, an almond rather than a parabola); ``top`` and
``bottom`` put each lid FDP on its margin. A lid FAP of ``d`` IRISD moves its margin
vertically in proportion to ``s(u)``, by exactly ``d * IRISD`` at its FDP (upper lid down,
lower lid up; both FAPs are bidirectional); at about 1024 + 0 the upper margin lies on the
lower. The lids stop where they meet: when the two requests
together exceed the opening, both are scaled back to leave :data:`MIN_OPENING` of it. An upper
lid opening wider is held at :data:`UPPER_OPEN` of its fade's height, a lower lid at half of its.

**The skin around them.** A vertex between the margins moves as the affine blend of the two
margins' moves at its height: the cover of a closed eye (a mask's triangles, a socket's
lining, the rim of an eye hole) is gathered to where the lids meet. Above the upper margin the
move fades linearly to 0 at ``reach * gap`` above it (the lid's skin up to its crease), below
the lower margin at :data:`LOWER_FADE` ``* reach * gap`` below it. Skin behind the margins fades out from
``depth * gap`` behind them to twice that: the inside of a closed socket stays, and the back
of the head is never in reach.

**A driven lid holds its skin.** MPEG-4's lid FAPs give the lid FDP's displacement from the
neutral face, so in a frame where an eye's lid FAPs move, the skin the lids own first gives back
its simulated drift (:func:`held_share`: all of it between the margins and at the corners,
fading out above and below over more than the lids' fades): the frontalis of a surprised face
dragged the upper margin up hardest under the brow's middle, and the lid's own raise laid over
that peaked and skewed the opening. The whole drift, not only its vertical part: the skin that
was dragged up was also drawn 1-2 mm forward, unevenly (ICT's upper lid in surprise), and a
margin put back on its curve in height but left at its dragged depths folded along its inner
half (all 12 of surprise's lid folds on ICT that the simulation did not have).

**An open jaw does not drag the upper lid** (``animate.eyelid_jaw_hold``, :func:`jaw_held_share`). In a
frame where the jaw moves and an eye's lids do not, its upper lid takes back the skin's drift with the
upper part of the hold: the jaw's pull, carried up the cheek by the skin sheet, dragged ICT's free upper
margin down 0.39 openings at full jawOpen (a notch in the margin); nothing asks the lid to move.

**Over the eyeball.** A lid closing over the eye rides forward over the eyeball: a vertex in
front of the eyeball's horizontal axis (along ``u``) keeps its distance from the axis as it
moves vertically, when that brings it forward; it never moves back (a lid opening wider
retracts straight up or down). Skin behind the margins' surface (the lid's lining) takes the
forward move of the surface in front of it (:func:`over_eyeball`). The eyeball's radius is taken
as :data:`EYEBALL_RADIUS` times ``half`` (a 12 mm eye in a 30 mm fissure), its centre behind the corners' midpoint, one
radius from the upper lid FDP.

**Gathered skin stays upright.** Where the lids meet, the skin between them is squeezed to
:data:`MIN_OPENING` of its height, and a few slivers near the corners (where the taper bends
fastest) can turn over. :class:`Eyelids` runs an
:class:`~faceforge.animation.guards.orientation.OrientationGuard` over the triangles in the lids'
reach, with a floor of half :data:`MIN_OPENING`, on each frame the lids moved. With
``animate.eyelid_fold_deg`` (80 by default; 0: off) the quads the lids move, flat at rest, are also
kept from bending past that dihedral (:func:`faceforge.pbd.dihedral_limit.limit_dihedrals`),
alternating with the guard (:data:`~faceforge.animation.lid_folds.FOLD_ROUNDS`): the lining gathered
onto the dipping line where the lids meet no longer folds at the canthi (the blinks).

**The margins stay where the FAPs put them.** Both passes move particles with inverse masses
(:mod:`faceforge.animation.lid_folds`): the lid margins (the vertices on each margin curve) and the
lid FDPs weigh 0, so the limit and the guard bend the skin around them and a full blink stays closed
to :data:`MIN_OPENING` (with equal masses the limit turned the margins too: the synthetic head's full
blink stayed 6 % open). Only near the corners, where the margins close onto each other, do they ease
free.

All lengths are in the skin's units; frames are in the head's frame (+X the subject's left,
+Y up, +Z forward).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from faceforge.animation.lid_folds import FOLD_ROUNDS, fold_quads, margin_inv_mass

#: FAP numbers of close_t_l_eyelid, close_t_r_eyelid, close_b_l_eyelid, close_b_r_eyelid
EYELID_FAPS = (19, 20, 21, 22)

#: per eye: (upper lid FDP, lower lid FDP, outer corner, inner corner, upper FAP, lower FAP)
EYES = (("3.1", "3.3", "3.7", "3.11", 19, 21),    # the subject's left eye
        ("3.2", "3.4", "3.12", "3.8", 20, 22))    # the subject's right eye

#: fraction of an eye's rest opening left between the margins when its lids meet
MIN_OPENING = 0.02

#: how far below the lower margin its move fades out, in the lid's reach (``reach x gap``; the
#: upper lid's skin fades over one reach): a lower lid raised a third of the opening (anger's
#: 350 IRISD, ICT 3.5 mm) over half a reach (2.5 mm on ICT) stretched the skin under it to twice
#: its height and turned the margin's rim over (ICT: anger's 4 lid folds -> 2, disgust's 3 -> 0)
LOWER_FADE = 1.0

#: how far the upper lid may open wider, as a fraction of its fade's height (``reach x gap``; the
#: skin it pushes into is squeezed to ``1 - UPPER_OPEN`` of its height there): at the default reach
#: (0.5) 0.375 openings, 3.7 mm on ICT's 10 mm eye. A real upper lid raise (AU5) is 2-4 mm on an
#: adult; MakeHuman's own "eye-opened-up" unit raises its lid FDP 312 IRISD (0.30 openings). At half
#: the fade (0.25 openings, as the lower lid) a wide-eyed surprise could not show the sclera above
#: the iris: its lids opened 1.30 times on every sample head whatever it asked past 256 IRISD
#: (docs/notes/read17.md)
UPPER_OPEN = 0.75

#: exponent of the margins' taper ``s(u)`` (module docstring)
TAPER = 3.0

#: eyeball radius as a fraction of half the eye's corner distance
EYEBALL_RADIUS = 0.8

#: how far beyond each eye corner (fraction of half the corner distance) a driven lid's hold on
#: the skin's drift fades out (:func:`held_share`)
HOLD_BEYOND = 0.6

#: how far above the upper margin and below the lower one a driven lid's hold fades out, in the
#: lid's reach (``reach x gap``): longer than the lids' own fades, so that the drift it takes back
#: (2-3 mm where a cheek raiser or the frontalis lifts the skin round the eye) changes by less than
#: half its height per reach; over one reach the held skin was sheared by most of its height and
#: creased the lower lid and the canthi (joy's 6 folded edges on MakeHuman, fear's 2, anger's 2);
#: below, three reaches: the tethered cheek raiser (``skin.cheek_tether``) lifts the skin under the
#: lower lid 5-6 mm at cheekSquint's full weight, and taking that back over two reaches still
#: creased MakeHuman's lower lid (3 folded edges per eye, 1 over three; FDP 5.3's lift stays out
#: of the hold's reach on the three samples)
HOLD_ABOVE, HOLD_BELOW = 1.5, 3.0

#: the jaw's pitch or yaw (radians) from which a moving jaw's drift of the upper lid is taken back
#: whole (``animate.eyelid_jaw_hold``, :func:`jaw_share`; jawOpen at full weight is ~0.4, jawLeft 0.1)
JAW_RAMP = 0.05


@dataclass(frozen=True)
class Eye:
    """One eye's frame from its FDPs (see the module docstring).

    centre : (3,) the corners' midpoint; axes : (3, 3) rows u (towards +X), v (up), w
    (forward), orthonormal and right-handed; half : half the corner distance; upper, lower :
    heights of the upper and lower lid FDP above ``centre`` along v; upper_u, lower_u : their
    places along u; lid_depth : their mean w; upper_fap, lower_fap : FAP numbers of the upper
    and lower lid.
    """

    centre: np.ndarray
    axes: np.ndarray
    half: float
    upper: float
    lower: float
    upper_u: float
    lower_u: float
    lid_depth: float
    upper_fap: int
    lower_fap: int

    @property
    def peak(self) -> float:
        """Where along u the margins are highest and lowest: the lid FDPs' mean u."""
        return 0.5 * (self.upper_u + self.lower_u)

    def taper(self, u) -> np.ndarray:
        """``s(u)`` in [0, 1] at places ``u`` along the corners (skin units from ``centre``):
        1 at :attr:`peak`, 0 at and beyond the corners (module docstring)."""
        u = np.asarray(u, dtype=np.float64)
        reach = np.where(u >= self.peak, self.half - self.peak, self.half + self.peak)
        return np.clip(1.0 - np.abs((u - self.peak) / reach) ** TAPER, 0.0, None)

    @property
    def margins(self) -> tuple[float, float]:
        """(top, bottom): heights of the upper and lower margin at :attr:`peak`, so that each
        margin ``top * s(u)``, ``bottom * s(u)`` passes through its lid FDP."""
        return (self.upper / float(self.taper(self.upper_u)),
                self.lower / float(self.taper(self.lower_u)))

    @property
    def gap(self) -> float:
        """The rest opening between the lid FDPs (skin units)."""
        return self.upper - self.lower

    @property
    def eyeball_centre(self) -> np.ndarray:
        """(3,) the centre of the eyeball the lids slide over."""
        r = EYEBALL_RADIUS * self.half
        ahead = np.sqrt(max(r * r - self.upper * self.upper, 0.0))
        return self.centre + (self.lid_depth - ahead) * self.axes[2]


def find_eyes(landmarks: dict) -> list[Eye]:
    """The eyes whose four FDPs ``landmarks {fdp: (3,)}`` holds (head frame, +Y up), 0, 1 or 2.

    An eye is skipped when its corners coincide, its upper lid FDP is not above its lower one
    (no opening to close), or a lid FDP lies out near a corner (the taper below 1/2 there).
    """
    eyes = []
    for upper, lower, outer, inner, upper_fap, lower_fap in EYES:
        if not all(f in landmarks for f in (upper, lower, outer, inner)):
            continue
        up, lo, o, i = (np.asarray(landmarks[f], dtype=np.float64).reshape(3)
                        for f in (upper, lower, outer, inner))
        u = o - i
        half = 0.5 * float(np.linalg.norm(u))
        if not half > 0.0:
            continue
        u = u / (2.0 * half)
        if u[0] < 0.0:
            u = -u
        v = np.array([0.0, 1.0, 0.0]) - u[1] * u
        if not np.linalg.norm(v) > 1e-9:
            continue
        v /= np.linalg.norm(v)
        w = np.cross(u, v)
        centre = 0.5 * (o + i)
        hu, hl = float((up - centre) @ v), float((lo - centre) @ v)
        if not hu > hl:
            continue
        depth = 0.5 * float((up - centre) @ w + (lo - centre) @ w)
        uu, ul = float((up - centre) @ u), float((lo - centre) @ u)
        eye = Eye(centre, np.stack([u, v, w]), half, hu, hl, uu, ul, depth, upper_fap, lower_fap)
        if not (abs(eye.peak) < half and eye.taper([uu, ul]).min() > 0.5):
            continue                            # a lid FDP out near a corner: no lid to move
        eyes.append(eye)
    return eyes


@dataclass(frozen=True)
class LidField:
    """How the skin near one eye follows its lids: a vertex ``i`` moves vertically (along the
    eye's v) by ``-up_share[i] * drop + low_share[i] * rise`` for an upper-lid drop and a
    lower-lid rise at the lid FDPs (skin units), see :func:`lid_field`. ``index (k,)``: the
    vertices in reach; the shares are (k,) >= 0 at those vertices (1 at the lid FDPs);
    ``reach``: the fade's height above the upper margin, in rest openings (:data:`LOWER_FADE` of it
    below the lower margin). ``hold (k,)`` in [0, 1]: how much of the skin's simulated drift the
    driven lids take back (:func:`held_share`): 1 between the margins, fading out :data:`HOLD_ABOVE`
    and :data:`HOLD_BELOW` reaches above and below them, without the taper along the lid, so the
    corners (the canthi, tied to the bone) are held as well, fading out beyond them over
    :data:`HOLD_BEYOND` of ``half``; None: the shares' sum. ``up_hold (k,)``: the upper lid's part of
    ``hold`` (above the upper margin and its share between the margins), what a moving jaw's drift is
    taken back with (:func:`jaw_held_share`); None: none."""

    eye: Eye
    index: np.ndarray
    up_share: np.ndarray
    low_share: np.ndarray
    reach: float
    hold: np.ndarray | None = None
    up_hold: np.ndarray | None = None


def lid_field(eye: Eye, rest: np.ndarray, reach: float = 0.5, depth: float = 0.5) -> LidField:
    """The share of each lid's move that each rest vertex ``rest (n, 3)`` takes.

    reach : how far above the upper margin the move fades to 0, in rest openings (:data:`LOWER_FADE`
    of it below the lower margin); depth : how far behind the margins skin starts to fade out, in
    rest openings (gone at twice that).
    """
    if not (reach > 0.0 and depth > 0.0):
        raise ValueError(f"reach and depth must be > 0, got {reach}, {depth}")
    rest = np.asarray(rest, dtype=np.float64).reshape(-1, 3)
    x = (rest - eye.centre) @ eye.axes.T
    g = eye.gap
    s = eye.taper(x[:, 0])
    top, bottom = eye.margins
    hu, hl = top * s, bottom * s
    behind = np.clip(2.0 - (eye.lid_depth * s - x[:, 2]) / (depth * g), 0.0, 1.0)
    above = np.clip(1.0 - (x[:, 1] - hu) / (reach * g), 0.0, 1.0)
    below = np.clip(1.0 - (hl - x[:, 1]) / (LOWER_FADE * reach * g), 0.0, 1.0)
    t = np.clip((x[:, 1] - hl) / np.maximum(hu - hl, 1e-300), 0.0, 1.0)   # 0 lower margin, 1 upper
    up = np.where(x[:, 1] >= hu, above, np.where(x[:, 1] <= hl, 0.0, t))
    low = np.where(x[:, 1] <= hl, below, np.where(x[:, 1] >= hu, 0.0, 1.0 - t))
    s_up, s_low = eye.taper([eye.upper_u, eye.lower_u])
    across = np.clip(((1.0 + HOLD_BEYOND) * eye.half - np.abs(x[:, 0])) / (HOLD_BEYOND * eye.half), 0.0, 1.0)
    # the hold fades farther than the lids' own moves (HOLD_ABOVE, HOLD_BELOW): a cheek raised under
    # the eye (joy's, fear's) drifts the lower lid up 2-3 mm, and taking that back within the lid's
    # own fade sheared the skin there by its own height (folds under the lower lid and at the canthi)
    below_hold = np.clip(1.0 - (hl - x[:, 1]) / (HOLD_BELOW * reach * g), 0.0, 1.0)
    above_hold = np.clip(1.0 - (x[:, 1] - hu) / (HOLD_ABOVE * reach * g), 0.0, 1.0)
    up_hold = np.where(x[:, 1] >= hu, above_hold, np.where(x[:, 1] <= hl, 0.0, t))
    low_hold = np.where(x[:, 1] <= hl, below_hold, np.where(x[:, 1] >= hu, 0.0, 1.0 - t))
    hold = np.clip(up_hold + low_hold, 0.0, 1.0) * across * behind
    up, low = up * s * behind / s_up, low * s * behind / s_low
    index = np.flatnonzero((up > 0.0) | (low > 0.0) | (hold > 0.0))
    up_hold = np.clip(up_hold, 0.0, 1.0) * across * behind
    return LidField(eye, index, up[index], low[index], float(reach), hold[index], up_hold[index])


def lid_moves(field: LidField, faps: np.ndarray, irisd: float) -> np.ndarray:
    """``(F, 2)`` (upper-lid drop, lower-lid rise) at the lid FDPs, skin units, from FAP frames
    ``faps (F, 68)`` (column k = FAP k + 1; NaN counts as 0) and one IRISD unit ``irisd``.

    Where the two would close more than the opening less :data:`MIN_OPENING`, both are scaled
    back to meet there (the margins' opening ``(top - bottom) s(u)`` is left that fraction
    everywhere along them). A lid that opens wider is held where the skin it pushes into is
    squeezed: ``UPPER_OPEN x reach`` openings up for the upper lid (:data:`UPPER_OPEN`),
    ``LOWER_FADE x reach / 2`` down for the lower one (half its height)."""
    faps = np.nan_to_num(np.atleast_2d(np.asarray(faps, dtype=np.float64)))
    eye = field.eye
    g = eye.gap
    move = faps[:, [eye.upper_fap - 1, eye.lower_fap - 1]] * irisd
    move = np.maximum(move, [-UPPER_OPEN * field.reach * g, -0.5 * LOWER_FADE * field.reach * g])
    top, bottom = eye.margins
    per_s = move / eye.taper([eye.upper_u, eye.lower_u])      # the moves at the margins' peak
    closing = per_s.sum(axis=1)
    most = (1.0 - MIN_OPENING) * (top - bottom)
    over = closing > most
    move[over] *= (most / closing[over])[:, None]
    return move


def held_share(field: LidField, moves: np.ndarray) -> np.ndarray:
    """``(F, k)`` in [0, 1]: how much of the simulated skin's drift (its whole displacement
    from rest) the lid field takes back at each vertex of ``field.index`` in frames whose lid moves are
    ``moves (F, 2)`` (:func:`lid_moves`). MPEG-4's lid FAPs give the lid FDP's displacement from
    the neutral face, so a driven lid's margin (share 1) goes where its FAP says whatever the
    muscles did to the skin around it (a brow raised by the frontalis dragged the upper margin up
    where the brow pulled hardest: a peaked, skewed eye opening in surprise). In a frame where
    either lid of the eye moves, both are held (a lid FAP of 0 is the neutral lid), with
    :attr:`LidField.hold`; in a frame where neither moves, nothing is."""
    moves = np.atleast_2d(moves)
    hold = np.clip(field.up_share + field.low_share, 0.0, 1.0) if field.hold is None else field.hold
    return np.any(moves != 0.0, axis=1)[:, None] * hold


def jaw_share(jaw) -> np.ndarray:
    """``(F,)`` in [0, 1]: how far the jaw DOFs ``jaw (F, 3)`` (pitch, yaw radians; protrusion) are
    from rest, 1 from :data:`JAW_RAMP` radians of pitch or yaw on (linear below it, so a take easing
    the jaw open eases the hold in)."""
    jaw = np.atleast_2d(np.asarray(jaw, dtype=np.float64))
    return np.clip(np.abs(jaw[:, :2]).max(axis=1) / JAW_RAMP, 0.0, 1.0)


def jaw_held_share(field: LidField, moves: np.ndarray, jaw, strength: float) -> np.ndarray:
    """``(F, k)`` in [0, 1]: how much of the skin's drift the upper lid takes back in frames whose lids
    do not move (``moves (F, 2)``, :func:`lid_moves`) while the jaw does (``jaw (F, 3)`` DOFs):
    ``strength x`` :func:`jaw_share` ``x`` :attr:`LidField.up_hold`; 0 in frames whose lids move (they
    hold the skin whole, :func:`held_share`) or with ``strength`` 0.

    ``animate.eyelid_jaw_hold``: an opening jaw pulls the skin of the cheek down, and through the skin
    between the cheek and the lid it drags the upper lid (ICT, whose lid margins are a free boundary:
    the margin up to 0.37 openings, 3.7 mm, at full jawOpen, and a notch where the limit stopped its
    fold). A real jaw leaves the upper lid where it is: nothing asks it to move. Frames without a jaw
    (brows, cheeks) keep their drift as before.
    """
    moves = np.atleast_2d(moves)
    if not strength or field.up_hold is None or jaw is None:
        return np.zeros((len(moves), len(field.index)))
    share = float(strength) * jaw_share(jaw) * ~np.any(moves != 0.0, axis=1)
    return share[:, None] * field.up_hold[None, :]


def lid_surface(eye: Eye, points: np.ndarray) -> np.ndarray:
    """``(k,)`` depth (along w, from :attr:`Eye.eyeball_centre`) of the margins' surface at the
    places along u of ``points (k, 3)``: ``lid_depth * s(u)``, the depth the lid FDPs and the
    margin curves lie at (module docstring)."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    ahead = float((eye.centre - eye.eyeball_centre) @ eye.axes[2])
    return ahead + eye.lid_depth * eye.taper((points - eye.centre) @ eye.axes[0])


def over_eyeball(y0: np.ndarray, z0: np.ndarray, y1: np.ndarray, surface: np.ndarray) -> np.ndarray:
    """``(L, k)`` forward moves (along w, >= 0) of vertices at heights ``y0 (k,)`` and depths
    ``z0 (k,)`` about the eyeball's centre moved vertically to ``y1 (L, k)``, ``surface (k,)`` the
    margins' depth at each (:func:`lid_surface`).

    A vertex at or in front of the margins' surface keeps its distance from the eyeball's axis
    (module docstring). A vertex behind it (the lining in the lid's thickness, a socket's rim) takes
    the forward move of the surface point in front of it at the same heights: it rides forward with
    the lid it is part of. Pushed only by its own height (as the surface's vertex was), the lining
    stayed back while the margin rode forward over it, and the rim folded between them: ICT's blinks,
    4 of eyeBlinkLeft's 18 folded edges and 2 of eyeBlinkRight's 17 on the lids over the rest face
    (MakeHuman's 4 / 4 and MediaPipe's 1 / 1 are elsewhere and unchanged).
    """
    zf = np.maximum(z0, surface)
    rho2 = y0 * y0 + zf * zf
    push = np.sqrt(np.maximum(rho2 - y1 * y1, 0.0)) - zf
    return np.where(zf > 0.0, np.maximum(push, 0.0), 0.0)


def move_lids(frames: np.ndarray, fields: list[LidField], faps: np.ndarray, irisd: float,
              rest: np.ndarray, jaw=None, jaw_hold: float = 0.0) -> np.ndarray:
    """Frames ``(F, n, 3)`` with the lids moved by FAPs 19-22 of ``faps (F, 68)``.

    fields : one :class:`LidField` per eye (of the same ``rest (n, 3)``); irisd : one IRISD
    unit (skin units). Each vertex in a field's reach is displaced by its vertical move, turned
    over the eyeball (module docstring), computed on its rest position and added to the frame.
    A driven lid first takes back the drift of the skin it holds (:func:`held_share`; the whole
    displacement from rest, module docstring), so its FDP ends exactly ``FAP x IRISD`` from its
    rest place. With ``jaw (F, 3)`` DOFs and ``jaw_hold`` > 0, the upper lid of an eye whose lids do
    not move takes back that share of its drift where the jaw moves (:func:`jaw_held_share`).
    A new array; frames without lid FAPs (nor, with ``jaw_hold``, a jaw) are copied bit for bit.
    No guard (:class:`Eyelids`).
    """
    out = np.array(frames, copy=True)
    rest = np.asarray(rest, dtype=np.float64).reshape(-1, 3)
    for field in fields:
        eye, idx = field.eye, field.index
        moves = lid_moves(field, faps, irisd)
        jawed = jaw_held_share(field, moves, jaw, jaw_hold)            # (F, k): undriven lids only
        if len(idx) and jawed.any():
            f = np.flatnonzero(jawed.any(axis=1))
            drift = out[np.ix_(f, idx)] - rest[idx]
            out[np.ix_(f, idx)] -= (jawed[f][..., None] * drift).astype(out.dtype)
        live = np.flatnonzero(np.any(moves != 0.0, axis=1))
        if not len(idx) or not len(live):
            continue
        hold = held_share(field, moves[live])                      # (L, k)
        if hold.any():   # a driven lid's margin goes where its FAP says, not where the skin dragged it
            drift = out[np.ix_(live, idx)] - rest[idx]                 # (L, k, 3): all of it
            out[np.ix_(live, idx)] -= (hold[..., None] * drift).astype(out.dtype)
        x = (rest[idx] - eye.eyeball_centre) @ eye.axes.T       # (k, 3) about the eyeball
        dv = -np.outer(moves[live, 0], field.up_share) + np.outer(moves[live, 1], field.low_share)
        y0, z0 = x[:, 1], x[:, 2]
        y1 = y0 + dv                                               # (L, k)
        z1 = z0 + over_eyeball(y0, z0, y1, lid_surface(eye, rest[idx]))
        d = dv[..., None] * eye.axes[1] + (z1 - z0)[..., None] * eye.axes[2]
        out[np.ix_(live, idx)] += d.astype(out.dtype)
    return out


class Eyelids:
    """The lids of a head's eyes, moved by FAPs 19-22 over finished frames.

    Parameters
    ----------
    rest : (n, 3) skin at rest; faces : (m, 3) int, its triangles
    landmarks : {fdp: (3,)} the neutral skin's FDPs (eyes without their four FDPs are skipped)
    irisd : one IRISD unit (skin units)
    reach, depth : see :func:`lid_field`
    fold_deg : ``animate.eyelid_fold_deg``: the skin the lids move, bent less than this (and
        :data:`~faceforge.animation.lid_folds.FOLD_FLAT_DEG`) at rest, is kept within this
        dihedral (degrees; 0: off)
    rigid : (n,) bool or None: vertices of pieces that ride a bone (eyeballs, teeth:
        :func:`faceforge.skin.parts.rigid_parts`); the lids never move them, and a lid FDP never
        names one of them as its lid

    Attributes: ``inv_mass (n,)``: the inverse masses the fold limit and (with it) the guard move
    the skin with, 0 on the margins and the lid FDPs
    (:func:`~faceforge.animation.lid_folds.margin_inv_mass`); all 1 with the limit off (the margins
    are then not looked for). ``lashes``: (lash vertices, lid vertices) of
    :func:`faceforge.animation.lashes.lash_carriers`: each lash vertex takes its lid vertex's move.
    """

    def __init__(self, rest, faces, landmarks: dict, irisd: float, reach: float = 0.5,
                 depth: float = 0.5, fold_deg: float = 0.0, jaw_hold: float = 0.0, rigid=None,
                 relative: bool = False):
        from faceforge.animation.guards.orientation import OrientationGuard
        from faceforge.animation.lashes import lash_carriers
        from faceforge.geometry.triangles import vertex_components

        self.rest = np.asarray(rest, dtype=np.float64).reshape(-1, 3)
        self.irisd = float(irisd)
        self.jaw_hold = float(jaw_hold)
        faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
        piece = vertex_components(len(self.rest), faces)
        rigid = np.zeros(len(self.rest), bool) if rigid is None else np.asarray(rigid, bool).reshape(-1)
        self.fields, self._lid_vertices = [], []
        for eye in find_eyes(landmarks):
            field = lid_field(eye, self.rest, reach, depth)
            # only the skin the lids belong to: an eyeball or a lash in the same mesh stays put
            fdps = next(e[:2] for e in EYES if e[4] == eye.upper_fap)
            lids = [int(np.argmin(np.linalg.norm(self.rest - np.asarray(landmarks[f], dtype=np.float64), axis=1)
                                  + np.where(rigid, np.inf, 0.0))) for f in fdps]
            self._lid_vertices.append(lids)
            keep = np.isin(piece[field.index], piece[lids]) & ~rigid[field.index]
            self.fields.append(replace(field, index=field.index[keep], up_share=field.up_share[keep],
                                       low_share=field.low_share[keep], hold=field.hold[keep],
                                       up_hold=field.up_hold[keep]))
        self.lashes = lash_carriers(self.rest, piece, rigid, self.fields)
        moving = np.zeros(len(self.rest), dtype=bool)
        for field in self.fields:
            moving[field.index] = True
        near = faces[moving[faces].any(axis=1)]
        self._fold = fold_quads(self.rest, faces, moving, fold_deg)
        # the fold limit and the guard bend the skin around the margins, they do not move them
        # (the inverse masses of lid_folds.margin_inv_mass); the lid FDPs are pinned whatever the mesh
        self.inv_mass = np.ones(len(self.rest))
        for field, lids in zip(self.fields, self._lid_vertices) if self._fold is not None else ():
            self.inv_mass = np.minimum(self.inv_mass, margin_inv_mass(field, self.rest, faces, depth))
            self.inv_mass[lids] = 0.0
        if self._fold is not None:   # built once: applied up to FOLD_ROUNDS times per frame the lids move
            from faceforge.pbd.dihedral_limit import DihedralLimit

            self._fold = DihedralLimit(*self._fold, len(self.rest), inv_mass=self.inv_mass)
        # animate.eyelid_fold_deg 0: the guard as it was (equal masses)
        self._guard = OrientationGuard(self.rest, near, min_area=0.5 * MIN_OPENING,
                                       inv_mass=None if self._fold is None else self.inv_mass) if len(near) else None
        # the jaw hold's take-back backed off where it would fold the skin or turn a triangle over
        self._jaw_blend = self._backing(faces, fold_deg)
        # animate.eyelid_relative: the limit and the guard held to each frame the lids are laid over
        self.relative = bool(relative) and self._guard is not None
        self._limit0 = None if self._fold is None else self._fold.limit.copy()
        self._floor0 = None if self._guard is None else self._guard.floor.copy()

    def _refer(self, frame: np.ndarray) -> None:
        """Hold the lids' fold limit and guard to ``frame (n, 3)``, the simulated frame the lids are laid
        over (``animate.eyelid_relative``): a quad it bends past the limit may stay as bent, a triangle it
        squeezes below the floor as low, one it turns over is left alone
        (:func:`~faceforge.animation.lid_folds.referred_limits`, :func:`~faceforge.animation.lid_folds.referred_floors`).
        The lids then straighten only what they bend: on the levelled risorius's rig the simulation left
        MakeHuman's outer canthi bent past the limit in pride.fap's jaw frames, and the limit and the guard,
        undoing each other over their 24 rounds, crept the corner 0.05-0.2 units in one frame."""
        from faceforge.animation.lid_folds import referred_floors, referred_limits

        if self._fold is not None:
            self._fold.set_limit(referred_limits(frame, self._fold.quads, self._limit0))
        g = self._guard
        g.floor = referred_floors(frame, g.faces, g.normal0, self._floor0)

    def _backing(self, faces, fold_deg: float):
        """:class:`faceforge.skin.fold_limit.BlendLimit` over the skin the jaw hold may take back: the
        take-back is a blend ``rest + (1 - share) (frame - rest)``, and where its share falls steeply
        (the canthi: held upper lid, free lower lid) it turned MediaPipe's corner triangles over past
        the lids' guard (pride.fap) and folded MakeHuman's; there it is backed off (:meth:`apply`)."""
        from faceforge.skin.fold_limit import BlendLimit, fold_limits
        if not self.jaw_hold or not self.fields:
            return None
        may = np.ones(len(self.rest))
        for field in self.fields:
            may[field.index] = np.minimum(may[field.index], 1.0 - self.jaw_hold * field.up_hold)
        folds = fold_limits(self.rest, faces, float(fold_deg or 0.0)) or (np.zeros((0, 4), np.int64), np.zeros(0))
        return BlendLimit(self.rest, may, *folds, faces=faces)

    def _straighten(self, frame: np.ndarray) -> None:
        """The lids' guard (and fold limit, ``animate.eyelid_fold_deg``, alternating) on ``frame``, in place."""
        if self._fold is None:
            self._guard.apply(frame)
        else:   # animate.eyelid_fold_deg: gathered skin neither turns over nor folds
            for _ in range(FOLD_ROUNDS):
                self._fold(frame, sweeps=1)
                self._guard.apply(frame)

    @property
    def faps(self) -> tuple[int, ...]:
        """The lid FAPs this head plays (those of the eyes it has)."""
        return tuple(sorted(f for field in self.fields for f in (field.eye.upper_fap, field.eye.lower_fap)))

    def apply(self, frames: np.ndarray, faps: np.ndarray, jaw=None) -> np.ndarray:
        """Frames ``(F, n, 3)`` (head frame) with the lids moved by ``faps (F, 68)``: a new
        array; frames where no lid moves are copied bit for bit. ``jaw (F, 3)``: the frames' jaw
        DOFs, for ``animate.eyelid_jaw_hold`` (:func:`jaw_held_share`; None: no jaw hold)."""
        out = move_lids(frames, self.fields, faps, self.irisd, self.rest, jaw, self.jaw_hold)
        if self._guard is None:
            return self._carry_lashes(frames, out)
        live = np.zeros(len(out), dtype=bool)
        kept = np.ones((len(out), len(self.rest)))   # 1 - the jaw hold's share taken back
        for field in self.fields:
            moves = lid_moves(field, faps, self.irisd)
            jawed = jaw_held_share(field, moves, jaw, self.jaw_hold)
            kept[:, field.index] = np.minimum(kept[:, field.index], 1.0 - jawed)
            live |= np.any(moves != 0.0, axis=1) | jawed.any(axis=1)
        for f in np.flatnonzero(live):
            if self.relative:
                self._refer(np.asarray(frames[f], dtype=np.float64))
            frame = np.ascontiguousarray(out[f], dtype=np.float64)
            held = frame.copy() if self._jaw_blend is not None and (kept[f] < 1.0).any() else None
            self._straighten(frame)
            bad = self._jaw_blend.below(frame) if held is not None else ((), ())
            if len(bad[0]) or len(bad[1]):   # the hold folded skin the lids' guard and limit did not right
                self._jaw_blend(held, np.asarray(frames[f], dtype=np.float64), kept[f], bad)
                frame = held
                self._straighten(frame)
            out[f] = frame
        return self._carry_lashes(frames, out)

    def _carry_lashes(self, frames, out):
        """``out`` with each lash vertex moved as its lid vertex was moved from ``frames`` (in place)."""
        lash, lid = self.lashes
        if len(lash):
            out[:, lash] += out[:, lid] - np.asarray(frames)[:, lid]
        return out
