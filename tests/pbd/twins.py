"""Plain-Python twins of the numba kernels: slow, obvious, one constraint at a time.

Each twin recomputes C and its gradient with numpy vectors in a Python loop and
applies the same PBD/XPBD update ``dp_i = s w_i grad_i C`` with
``s = (-k C - c D lam) / (D (1 + c))``; the tests compare them with the kernels.
"""

from __future__ import annotations

import math

import numpy as np

from faceforge.pbd.constraints.bending import MAX_STEP_ANGLE


def _apply(x, w, ids, grads, value, k, c, lam):
    denom = sum(w[i] * float(g @ g) for i, g in zip(ids, grads))
    if denom <= 0.0:
        return 0.0
    s = (-k * value - c * denom * lam) / (denom * (1.0 + c))
    for i, g in zip(ids, grads):
        x[i] = x[i] + s * w[i] * g
    return s


def distance(x, w, pairs, rest, k, c=None, lam=None, weight=None):
    """``weight (m, 2)``: the inverse masses each constraint shares its correction by (default
    ``w``); an end with ``w`` 0 does not move."""
    x = x.copy()
    m = len(pairs)
    c = np.zeros(m) if c is None else c
    lam = np.zeros(m) if lam is None else lam.copy()
    for j, (a, b) in enumerate(pairs):
        d = x[a] - x[b]
        n = float(np.linalg.norm(d))
        wa, wb = (w[a], w[b]) if weight is None else weight[j]
        if n == 0.0 or wa + wb == 0.0:
            continue
        s = (-k[j] * (n - rest[j]) - c[j] * (wa + wb) * lam[j]) / ((wa + wb) * (1.0 + c[j]))
        lam[j] += s
        x[a] = x[a] + s * (wa if w[a] > 0 else 0.0) * d / n
        x[b] = x[b] - s * (wb if w[b] > 0 else 0.0) * d / n
    return x, lam


def _sin_cos(p0, p1, p2, p3):
    e = p1 - p0
    na = np.cross(e, p2 - p0)
    nb = np.cross(p0 - p1, p3 - p1)
    return float(np.cross(na, nb) @ e) / float(np.linalg.norm(e)), float(na @ nb)


def deviation(sin, cos, rest):
    """theta - rest from the (sin, cos) pair, as the kernel: Padé atan near 0, else atan2."""
    y = sin * math.cos(rest) - cos * math.sin(rest)
    x = cos * math.cos(rest) + sin * math.sin(rest)
    if x > 0 and abs(y) <= 0.25 * x:
        z = y / x
        z2 = z * z
        return z * (945.0 + z2 * (735.0 + 64.0 * z2)) / (945.0 + z2 * (1050.0 + 225.0 * z2))
    return math.atan2(y, x)


def bending_gradient(p0, p1, p2, p3):
    """Gradient of the signed dihedral angle (Bridson et al. 2003), four (3,) vectors."""
    e = p1 - p0
    el = float(np.linalg.norm(e))
    na = np.cross(e, p2 - p0)
    nb = np.cross(p0 - p1, p3 - p1)
    a = na / float(na @ na)
    b = nb / float(nb @ nb)
    return (-float((p2 - p1) @ e) / el * a - float((p3 - p1) @ e) / el * b,
            float((p2 - p0) @ e) / el * a + float((p3 - p0) @ e) / el * b,
            -el * a, -el * b)


def bending(x, w, quads, rest, k, c=None, lam=None):
    x = x.copy()
    m = len(quads)
    c = np.zeros(m) if c is None else c
    lam = np.zeros(m) if lam is None else lam.copy()
    for j, q in enumerate(quads):
        p = [x[i] for i in q]
        e = p[1] - p[0]
        na = np.cross(e, p[2] - p[0])
        nb = np.cross(p[0] - p[1], p[3] - p[1])
        ee = float(e @ e)
        if ee == 0 or na @ na <= 1e-24 * ee * ee or nb @ nb <= 1e-24 * ee * ee:
            continue
        value = deviation(*_sin_cos(*p), rest[j])
        if not c[j]:   # PBD (no compliance): one projection turns by at most MAX_STEP_ANGLE
            value = min(max(value, -MAX_STEP_ANGLE), MAX_STEP_ANGLE)
        lam[j] += _apply(x, w, q, bending_gradient(*p), value, k[j], c[j], lam[j])
    return x, lam


def area(x, w, tris, rest, k, c=None, lam=None):
    x = x.copy()
    m = len(tris)
    c = np.zeros(m) if c is None else c
    lam = np.zeros(m) if lam is None else lam.copy()
    for j, (a, b, d) in enumerate(tris):
        n = np.cross(x[b] - x[a], x[d] - x[a])
        nl = float(np.linalg.norm(n))
        if nl == 0.0:
            continue
        u = n / nl
        grads = (0.5 * np.cross(u, x[d] - x[b]), 0.5 * np.cross(u, x[a] - x[d]),
                 0.5 * np.cross(u, x[b] - x[a]))
        lam[j] += _apply(x, w, (a, b, d), grads, 0.5 * nl - rest[j], k[j], c[j], lam[j])
    return x, lam


def volume(x, w, tris, rest, k, ref):
    """One body; ``ref``: global ids of the reference particles."""
    x = x.copy()
    r = x[ref].mean(axis=0)
    grads = {}
    vol = 0.0
    for a, b, d in tris:
        pa, pb, pd = x[a] - r, x[b] - r, x[d] - r
        vol += float(pa @ np.cross(pb, pd)) / 6.0
        for i, g in ((a, np.cross(pb, pd)), (b, np.cross(pd, pa)), (d, np.cross(pa, pb))):
            grads[i] = grads.get(i, 0.0) + g / 6.0
    total = sum(grads.values())
    for i in ref:
        grads[i] = grads[i] - total / len(ref)
    ids = sorted(grads)
    _apply(x, w, ids, [grads[i] for i in ids], vol - rest, k, 0.0, 0.0)
    return x


def position(x, w, particles, targets, k):
    x = x.copy()
    for j, i in enumerate(particles):
        if w[i] > 0:
            x[i] = x[i] + k[j] * (targets[j] - x[i])
    return x


def attachment(x, w, particles, tris, bary, k):
    x = x.copy()
    for j, i in enumerate(particles):
        t = bary[j] @ x[tris[j]]
        if w[i] > 0:
            x[i] = x[i] + k[j] * (t - x[i])
    return x


def step(model, x_in, v_in, control, dt, iterations, substeps, damping, gravity=0.0):
    """Plain-Python twin of ``Solver.step`` (PBD 'paper' mode, builder order)."""
    from faceforge.pbd.constraints.volume import reference_vertices

    m = model
    w = m.inv_mass
    x = x_in.copy()
    v = v_in.copy()
    kin = m.kinematic_indices
    start = x[kin].copy()
    h = dt / substeps
    damp = (1.0 - damping) ** (1.0 / substeps)
    for s in range(substeps):
        prev = x.copy()
        for i in range(len(x)):
            if w[i] > 0:
                v[i] = v[i] * damp + h * np.array([0.0, -gravity, 0.0])
                x[i] = prev[i] + h * v[i]
        alpha = (s + 1.0) / substeps
        x[kin] = control.kinematic_positions if s == substeps - 1 else \
            start + alpha * (control.kinematic_positions - start)
        for _ in range(iterations):
            for kind, a, b in m.blocks:
                sl = slice(a, b)
                if kind == 0:
                    x, _ = distance(x, w, m.distance_indices[sl], m.distance_rest_length[sl],
                                    m.distance_stiffness[sl], weight=m.distance_weight[sl])
                elif kind == 1:
                    x, _ = bending(x, w, m.bending_indices[sl], m.bending_rest_angle[sl],
                                   m.bending_stiffness[sl])
                elif kind == 2:
                    x, _ = area(x, w, m.area_indices[sl], m.area_rest_area[sl], m.area_stiffness[sl])
                elif kind == 3:
                    ts = m.volume_triangle_start
                    for j in range(a, b):
                        tris = m.volume_triangles[ts[j]:ts[j + 1]]
                        x = volume(x, w, tris, m.volume_rest_volume[j], m.volume_stiffness[j],
                                   reference_vertices(tris))
                elif kind == 4:
                    x = position(x, w, m.position_indices[sl], control.position_targets[sl],
                                 m.position_stiffness[sl])
                else:
                    x = attachment(x, w, m.attachment_indices[sl], m.attachment_triangles[sl],
                                   m.attachment_bary[sl], m.attachment_stiffness[sl])
        v = (x - prev) / h
    return x, v
