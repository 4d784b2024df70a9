"""Keep the eye sockets hollow: an orbit-specific step of the fit (§7).

Some heads model the skin of the closed eye socket: behind the lids the skin folds
inward and lines a cavity where the eyeball sits (MakeHuman: a closed pocket ~25 mm
deep). The template orbit, morphed by the landmark RBF, is shallower than such a pocket,
so the bone fills part of it, and pushing single bone vertices out with RBF landmarks
folds the thin orbital walls over each other. The region inside the pocket must be
empty of bone: that is what this module enforces, with a map that cannot fold.

**The hollow.** Behind each eye (midpoint of the eye corners, moved back along -Z by a
fraction of the corner distance) a centre ``c`` is sought from which the skin encloses a
pocket: rays cast from ``c`` in every direction first meet either the socket lining from
its outer side (skin normal facing ``c``) or the virtual fan closing the eye opening
(:meth:`faceforge.fit.surface.SkinSurface.build`). Its radius in direction ``u`` is the
distance ``t(u)`` of that first hit; the bone must stay beyond ``T(u) = t(u) + clearance``.
Heads with eye holes and no socket (ICT, MediaPipe) have no such centre: rays from behind
their eye openings meet the skin from inside, and no hollow is found.

**The map.** Every point ``x = c + r u`` is moved along its own ray, ``x -> c + T F(r/T) u``
with the piecewise-linear profile (``lam``: the smallest ``r/T`` of bone inside the hollow;
``beta``: the blend width and ``delta = LAYER * beta`` the layer the bone inside is pressed
into, both as fractions of ``T``)

    F(rho) = rho + (1 - lam)                                   rho < lam
    F(rho) = 1 + delta (rho - lam) / (1 - lam)                 lam <= rho <= 1
    F(rho) = 1 + delta + (rho - 1) (beta - delta) / beta       1 < rho <= 1 + beta
    F(rho) = rho                                               rho > 1 + beta

``F`` is continuous and increasing, and ``F(lam) = 1``: bone that was inside ends pressed
against the socket, at least ``clearance`` beyond its skin, in a layer ``delta T`` thick;
bone outside the socket moves by at most ``delta T`` and bone beyond ``(1 + beta) T`` not
at all. Each ray is mapped into itself by an increasing function, so the map is
one-to-one: it cannot fold the bone, and a bone that did not intersect itself still does
not. The fit appends it to its map, so the muscles, landmarks and jaw axes move with the
bone.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

#: (outer corner, inner corner) FDPs of the subject's left and right eye
EYE_CORNERS = (("3.7", "3.11"), ("3.12", "3.8"))


def fibonacci_directions(n: int) -> np.ndarray:
    """(n, 3) unit vectors spread evenly over the sphere (golden-angle spiral)."""
    i = np.arange(n, dtype=np.float64) + 0.5
    z = 1.0 - 2.0 * i / n
    phi = np.pi * (3.0 - np.sqrt(5.0)) * i
    s = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    return np.stack([s * np.cos(phi), s * np.sin(phi), z], axis=1)


#: the layer bone inside a socket is pressed into, as a fraction of the blend width
LAYER = 0.2
#: the map's rays see the socket skin up to this many times the hollow's ``reach`` (the
#: farthest hit of the rays that found it, which sample the socket: a little slack)
REACH_SLACK = 1.5


def radial_profile(rho: np.ndarray, lam: float, beta: float) -> np.ndarray:
    """``F(rho)`` of the module docstring; ``rho`` (k,) radius / T, ``0 < lam < 1``, ``beta > 0``."""
    rho = np.asarray(rho, dtype=np.float64)
    delta = LAYER * beta
    pressed = 1.0 + delta * (rho - lam) / (1.0 - lam)
    blend = 1.0 + delta + (rho - 1.0) * (beta - delta) / beta
    return np.where(rho < lam, rho + (1.0 - lam),
                    np.where(rho <= 1.0, pressed, np.where(rho <= 1.0 + beta, blend, rho)))


def chord_sag(length: float, radius: float) -> float:
    """How far a straight chord of ``length`` between two points on a circle of ``radius``
    dips inside it (same units): ``R - sqrt(R^2 - L^2 / 4)``, about ``L^2 / (8 R)`` for a short
    chord and never more than ``R`` (a chord longer than the diameter is taken as the diameter).
    The small-chord formula alone grows without bound: an edge stretched to four socket
    radii by the enhancement flows (MakeHuman ``caucasian_female_young``) asked for a
    clearance of 2.5 head units, ten times the socket, and the map blew the skull up into a
    sphere around the head."""
    r = float(radius)
    half = min(0.5 * float(length), r)
    return r - float(np.sqrt(max(r * r - half * half, 0.0)))


@dataclass(frozen=True)
class OrbitHollow:
    """The hollow behind one eye and the map that clears bone out of it.

    centre (3,) head units; caster: :class:`faceforge.geometry.rays.RayCaster` of the skin
    (fans included); clearance: bone kept this far beyond the socket skin (head units);
    reach: the farthest socket skin from the centre, socket_radius: the median distance
    (head units); lam, beta: the profile (``lam`` is set by :meth:`fitted` from the bone; 1
    leaves every point in place).
    """

    centre: np.ndarray
    caster: object
    clearance: float
    reach: float
    beta: float = 0.5
    lam: float = 1.0
    socket_radius: float = 0.0
    face_normal: np.ndarray = None   # (m, 3) the skin's outward face normals (with fan_face: see radius)
    fan_face: np.ndarray = None      # (m,) bool: faces of the fans closing the skin's holes

    def radius(self, points: np.ndarray):
        """``(r (k,), u (k, 3), T (k,))`` of points (k, 3): distance from the centre, unit
        direction, and the bone's least distance ``t(u) + clearance`` along that direction
        (``inf`` where the ray meets no skin within :data:`REACH_SLACK` times ``reach``: no
        constraint). Without that
        bound a ray leaving the pocket through a gap (up to a tenth of the directions may,
        :func:`find_hollow`) met the far side of the head, and the map pushed the bone out by
        a head's size there: the skull blew up into a sphere around the head (MakeHuman
        ``caucasian_female_young``, tests/fit/test_fit_orbits_reach.py)."""
        d = np.asarray(points, dtype=np.float64).reshape(-1, 3) - self.centre
        r = np.linalg.norm(d, axis=1)
        u = d / np.maximum(r, 1e-300)[:, None]
        u[r == 0] = (0.0, 0.0, -1.0)
        face, _, t = self.caster.first_hit(np.broadcast_to(self.centre, u.shape), u,
                                            max_distance=REACH_SLACK * self.reach)
        if self.face_normal is not None:
            # a ray that meets the skin from inside (its outward normal along the ray, not a
            # fan) leaves the head there: the centre sees flesh, not the socket, that way, and
            # bone along it stays. Bounding it by ``t`` pushed that bone out through the lids
            # (MakeHuman caucasian_female_young with detected eye corners: skull 95 % inside)
            hit = face >= 0
            f = face[hit]
            leaves = np.einsum("ij,ij->i", self.face_normal[f], u[hit]) > 0.0
            if self.fan_face is not None:
                leaves &= ~self.fan_face[f]
            t[np.flatnonzero(hit)[leaves]] = np.inf
        return r, u, t + self.clearance

    def near(self, points: np.ndarray) -> np.ndarray:
        """Bool (k,): points within ``(1 + beta)`` times the reach of the centre (the only
        ones the map can move)."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        return np.linalg.norm(p - self.centre, axis=1) < (1.0 + self.beta) * (self.reach + self.clearance)

    def inside(self, points: np.ndarray, tol: float = 0.0) -> np.ndarray:
        """Bool (k,): points closer to the centre than the bone may come (``r < T(u) + tol``)."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        out = np.zeros(len(p), bool)
        m = self.near(p)
        if m.any():
            r, _, big_t = self.radius(p[m])
            out[m] = (r < big_t + tol) & np.isfinite(big_t)    # inf: no constraint that way
        return out

    def fitted(self, bone_points: np.ndarray, margin: float = 0.9) -> "OrbitHollow":
        """This hollow with ``lam`` set so that every bone point (k, 3) now inside it ends
        outside: ``lam = margin * min(r / T)`` over those points (1: none inside)."""
        p = np.asarray(bone_points, dtype=np.float64).reshape(-1, 3)
        m = self.near(p)
        if not m.any():
            return replace(self, lam=1.0)
        r, _, big_t = self.radius(p[m])
        rho = r / big_t
        inside = rho < 1.0          # (T = inf: the ray leaves the skin; rho = 0 there is not inside)
        inside &= np.isfinite(big_t)
        if not inside.any():
            return replace(self, lam=1.0)
        return replace(self, lam=float(max(margin * rho[inside].min(), 1e-3)))

    def with_chord_margin(self, vertices: np.ndarray, faces: np.ndarray) -> "OrbitHollow":
        """This hollow with the clearance raised by the sag ``L^2 / (8 R)`` of the longest edge
        ``L`` of the mesh ``(vertices (n, 3), faces (m, 3))`` near it on a socket of radius
        ``R``: the map places vertices, and a straight edge between two of them, each clear
        of the curved socket, dips towards it by that much."""
        v = np.asarray(vertices, dtype=np.float64)
        f = np.asarray(faces, dtype=np.int64)
        e = np.vstack([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
        near = self.near(0.5 * (v[e[:, 0]] + v[e[:, 1]]))
        if not near.any() or self.socket_radius <= 0.0:
            return self
        length = float(np.linalg.norm(v[e[near, 0]] - v[e[near, 1]], axis=1).max())
        return replace(self, clearance=self.clearance + chord_sag(length, self.socket_radius))

    def __call__(self, points) -> np.ndarray:
        p = np.asarray(points, dtype=np.float64)
        flat = p.reshape(-1, 3).copy()
        if self.lam >= 1.0 or len(flat) == 0:
            return flat.reshape(p.shape)
        m = np.flatnonzero(self.near(flat))
        if len(m):
            r, u, big_t = self.radius(flat[m])
            ok = np.isfinite(big_t)
            m, r, u, big_t = m[ok], r[ok], u[ok], big_t[ok]
            flat[m] = self.centre + (big_t * radial_profile(r / big_t, self.lam, self.beta))[:, None] * u
        return flat.reshape(p.shape)


def fit_hollow(hollow: OrbitHollow, vertices: np.ndarray, faces: np.ndarray, passes: int = 2) -> OrbitHollow:
    """The hollow's map for the bone mesh ``(vertices (n, 3), faces (m, 3))``: the chord
    margin (:meth:`OrbitHollow.with_chord_margin`) and ``lam`` (:meth:`OrbitHollow.fitted`).
    The map stretches the edges it pulls out of the socket, so the margin is measured again
    on the mapped mesh, ``passes`` times in all."""
    v = np.asarray(vertices, dtype=np.float64)
    h, mapped = hollow, v
    for _ in range(max(1, passes)):
        h = hollow.with_chord_margin(mapped, faces).fitted(v)
        mapped = h(v)
    return h


def find_hollow(skin, centre_candidates: np.ndarray, clearance: float, max_radius: float,
                beta: float = 0.5, n_directions: int = 256, min_enclosed: float = 0.9):
    """The best hollow among candidate centres (c, 3), or None.

    A centre encloses a hollow when at least ``min_enclosed`` of ``n_directions`` rays from
    it first meet the skin within ``max_radius`` either on the socket lining from outside
    (the face's outward normal facing the centre) or on a fan closing a hole. The candidate with
    the first (most forward) enclosing candidate wins: rays from a centre near the eye
    opening push bone at the rim sideways and bone behind the eye backwards, as an orbit
    (a cone opening forward) is shaped.
    """
    dirs = fibonacci_directions(n_directions)
    fan_face = np.zeros(len(skin.faces), bool)
    if skin.n_real >= 0:
        fan_face = (skin.faces >= skin.n_real).any(axis=1)
    tri = skin.vertices[skin.faces]
    face_normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])   # outward winding, unnormalised
    for c in np.asarray(centre_candidates, dtype=np.float64).reshape(-1, 3):
        face, _, t = skin.caster.first_hit(np.broadcast_to(c, dirs.shape), dirs)
        hit = (face >= 0) & (t <= max_radius)
        enclosed = np.zeros(len(dirs), bool)
        if hit.any():
            f = face[hit]
            enclosed[hit] = fan_face[f] | (np.einsum("ij,ij->i", face_normal[f], dirs[hit]) < 0.0)
        if enclosed.mean() >= min_enclosed:
            return OrbitHollow(c, skin.caster, float(clearance), float(t[hit].max()), float(beta),
                               socket_radius=float(np.median(t[hit])), face_normal=face_normal,
                               fan_face=fan_face)
    return None


def find_orbit_hollows(skin, skin_landmarks: dict, clearance: float, beta: float = 0.5,
                       depths=(0.0, 0.1, 0.2, 0.3, 0.4, 0.5)) -> list[OrbitHollow]:
    """The hollows behind the eyes (0, 1 or 2) of a skin.

    skin : :class:`faceforge.fit.surface.SkinSurface`; skin_landmarks {fdp: (3,)} (the eye
    corners 3.7, 3.11, 3.8, 3.12 are used; an eye without both corners is skipped).
    Centres are tried at the corners' midpoint moved back (-Z) by ``depths`` times the
    corner distance; rays count up to 1.5 corner distances.
    """
    out = []
    for outer, inner in EYE_CORNERS:
        if outer not in skin_landmarks or inner not in skin_landmarks:
            continue
        a, b = np.asarray(skin_landmarks[outer], float), np.asarray(skin_landmarks[inner], float)
        width = float(np.linalg.norm(a - b))
        mid = 0.5 * (a + b)
        cands = mid - np.asarray(depths, dtype=np.float64)[:, None] * width * np.array([0.0, 0.0, 1.0])
        h = find_hollow(skin, cands, clearance, 1.5 * width, beta)
        if h is not None:
            out.append(h)
    return out
