"""The compiled time step: predict, project in builder order, update velocities.

One numba function runs a whole ``Solver.step`` (all substeps and iterations) so
that no Python code runs per particle or per constraint. Blocks are dispatched by
kind; inside a block the per-kind sweep calls the pure constraint function.
"""

from __future__ import annotations

import numba

from faceforge.pbd.constraints._common import PBD_NUMBA

from faceforge.pbd.constraints.area import _project_area, _project_area_batched
from faceforge.pbd.constraints.attachment import _project_attachment
from faceforge.pbd.constraints.bending import _project_bending, _project_bending_batched
from faceforge.pbd.constraints.distance import (
    _project_distance, _project_distance_batched, _project_distance_pbd)
from faceforge.pbd.constraints.position import _project_position
from faceforge.pbd.constraints.quad import _project_quads_batched
from faceforge.pbd.constraints.volume import _project_volume, _solve_volume_parts, _volume_apply

#: solver-only block kinds: a bending block fused with its quads' stretches (PBD, coloured),
#: and such a block that also projects one area constraint per quad
QUAD = 6
QUAD_AREA = 7


@numba.njit(**PBD_NUMBA)
def _project(x, w, blocks, iterations, xpbd,
             d_idx, d_rest, d_k, d_c, d_lam, d_coef, d_runs, d_coef_t, d_wt,
             b_idx, b_rest, b_k, b_c, b_lam, b_runs, b_w, b_rest_t, q_stretch, q_area,
             q_area_stop,
             a_idx, a_rest, a_k, a_c, a_lam, a_runs, a_w, buf,
             v_pstart, v_part, v_pcuts, v_cuts, v_tris, v_rstart, v_ref, v_rest, v_k, v_c, v_lam, v_g,
             p_idx, p_target, p_k, p_c, p_lam,
             t_idx, t_tri, t_bary, t_k, t_c, t_lam):
    """``iterations`` Gauss-Seidel sweeps over ``blocks (nb, 3)`` rows (kind, start, stop).

    ``d_runs`` / ``b_runs`` / ``a_runs`` (runs of independent distance / bending / area
    constraints, empty unless colouring in a PBD mode) select the vectorised sweeps
    (``d_coef_t (3, m)``: ``d_coef`` transposed; ``d_wt (m, 3)``: the XPBD sweep's weights,
    ``distance.move_weights``); ``buf`` is their scratch, ``b_w (4, m)`` /
    ``a_w (3, m)`` their per-constraint inverse masses and ``b_rest_t (2, m)`` the rest
    cosines and sines. ``d_coef (m, 3)``: the PBD distance data (see
    ``distance.pbd_coefficients``); ``q_stretch (6, m_bending)``: the stretches fused into
    the quads of ``QUAD`` blocks (transposed ``quad.stretch_table``); ``q_area
    (3, m_bending)``: the area constraints fused into the quads of ``QUAD_AREA`` blocks
    (transposed ``quad.area_table``); ``q_area_stop (runs - 1,)``: per bending run, the end
    of its quads with a fused area (``quad.areas_first``).
    """
    for _ in range(iterations):
        for b in range(blocks.shape[0]):
            kind = blocks[b, 0]
            start = blocks[b, 1]
            stop = blocks[b, 2]
            if kind == 0:
                if xpbd:
                    _project_distance(x, d_wt, d_idx, d_rest, d_k, d_c, d_lam, True, start, stop)
                elif d_runs.shape[0] > 1:  # coloured, PBD modes: vectorised batches
                    _project_distance_batched(x, d_idx, d_coef_t, d_runs, buf, start, stop)
                else:
                    _project_distance_pbd(x, d_idx, d_coef, start, stop)
            elif kind == 1:
                if b_runs.shape[0] > 1:  # coloured, PBD modes: vectorised batches
                    _project_bending_batched(x, b_idx, b_w, b_rest_t, b_k, b_runs, buf, start, stop)
                else:
                    _project_bending(x, w, b_idx, b_rest, b_k, b_c, b_lam, xpbd, start, stop)
            elif kind == 2:
                if a_runs.shape[0] > 1:
                    _project_area_batched(x, a_idx, a_w, a_rest, a_k, a_runs, buf, start, stop)
                else:
                    _project_area(x, w, a_idx, a_rest, a_k, a_c, a_lam, xpbd, start, stop)
            elif kind == 3:
                _project_volume(x, w, v_pstart, v_part, v_pcuts, v_cuts, v_tris, v_rstart, v_ref,
                                v_rest, v_k, v_c, v_lam, v_g, xpbd, start, stop)
            elif kind == 4:
                _project_position(x, w, p_idx, p_target, p_k, p_c, p_lam, xpbd, start, stop)
            elif kind == 5:
                _project_attachment(x, w, t_idx, t_tri, t_bary, t_k, t_c, t_lam, xpbd, start, stop)
            else:  # QUAD (bending fused with its quads' stretches), QUAD_AREA (and areas)
                _project_quads_batched(x, b_idx, b_w, b_rest_t, b_k, q_stretch, q_area,
                                       kind == 7, b_runs, q_area_stop, buf, start, stop)


@numba.njit(parallel=True, **PBD_NUMBA)
def _project_parts(x, w, blocks, seg, iterations, xpbd,
                   d_idx, d_rest, d_k, d_c, d_lam, d_coef, d_runs, d_coef_t, d_wt,
                   b_idx, b_rest, b_k, b_c, b_lam, b_runs, b_w, b_rest_t, q_stretch, q_area,
                   q_area_stop,
                   a_idx, a_rest, a_k, a_c, a_lam, a_runs, a_w, bufs,
                   v_pstart, v_part, v_pcuts, v_cuts, v_tris, v_rstart, v_ref, v_rest, v_k, v_c,
                   v_lam, v_g, p_idx, p_target, p_k, p_c, p_lam,
                   t_idx, t_tri, t_bary, t_k, t_c, t_lam):
    """:func:`_project` over particle-disjoint parts (:mod:`faceforge.pbd.partition`): per
    iteration, the block rows ``seg[p]:seg[p + 1]`` of every part ``p < n`` at once (one
    thread each, scratch ``bufs[p]``), then the seam's rows ``seg[n]:seg[n + 1]``. Without a
    seam the parts never meet, so each runs all its iterations in one go (the same result).

    A volume body projected last in the seam leaves its update (``x += f w g``, its gradient
    cleared) to the next iteration's launch, each part applying it to its own particles before
    projecting them (nothing reads them in between: the same bytes as updating at once), and
    to the end of the step after the last iteration."""
    n = seg.shape[0] - 2
    seam = seg[n + 1] > seg[n]
    last = seg[n + 1] - 1
    pend = -1     # a seam body's volume update left to the next parts' launch (see below)
    pend_f = 0.0
    pend_moved = False
    for _ in range(iterations if seam else 1):
        reps = 1 if seam else iterations
        for p in numba.prange(n):
            if pend >= 0:  # the last iteration's update of the body, on this part's particles
                ps = v_pstart[pend]
                _volume_apply(x, w, v_part[ps + v_pcuts[pend, p]:ps + v_pcuts[pend, p + 1]], v_g,
                              pend_f, pend_moved)
            _project(x, w, blocks[seg[p]:seg[p + 1]], reps, xpbd,
                     d_idx, d_rest, d_k, d_c, d_lam, d_coef, d_runs, d_coef_t, d_wt,
                     b_idx, b_rest, b_k, b_c, b_lam, b_runs, b_w, b_rest_t, q_stretch, q_area,
                     q_area_stop, a_idx, a_rest, a_k, a_c, a_lam, a_runs, a_w, bufs[p],
                     v_pstart, v_part, v_pcuts, v_cuts, v_tris, v_rstart, v_ref, v_rest, v_k, v_c,
                     v_lam, v_g, p_idx, p_target, p_k, p_c, p_lam,
                     t_idx, t_tri, t_bary, t_k, t_c, t_lam)
        if pend >= 0:  # and on its particles of no part
            ps = v_pstart[pend]
            _volume_apply(x, w, v_part[ps + v_pcuts[pend, n]:ps + v_pcuts[pend, n + 1]], v_g,
                          pend_f, pend_moved)
            pend = -1
        for r in range(seg[n], seg[n + 1]):
            if blocks[r, 0] == 3:  # a body joining parts: its rows and sums part by part at once
                for j in range(blocks[r, 1], blocks[r, 2]):
                    # the seam's last projection: nothing reads the body's particles before the
                    # next iteration's parts, which apply its update on their own particles
                    defer = r == last and j == blocks[r, 2] - 1
                    s, f6, moved = _solve_volume_parts(
                        x, w, v_part[v_pstart[j]:v_pstart[j + 1]], v_pcuts[j], v_tris, v_cuts[j],
                        v_ref[v_rstart[j]:v_rstart[j + 1]], v_rest[j], v_k[j], v_c[j], v_lam[j],
                        v_g, xpbd, bufs, defer)
                    v_lam[j] += s
                    if defer:
                        pend, pend_f, pend_moved = j, f6, moved
            else:
                _project(x, w, blocks[r:r + 1], 1, xpbd,
                         d_idx, d_rest, d_k, d_c, d_lam, d_coef, d_runs, d_coef_t, d_wt,
                         b_idx, b_rest, b_k, b_c, b_lam, b_runs, b_w, b_rest_t, q_stretch,
                         q_area, q_area_stop, a_idx, a_rest, a_k, a_c, a_lam, a_runs, a_w,
                         bufs[0], v_pstart, v_part, v_pcuts, v_cuts, v_tris, v_rstart, v_ref, v_rest,
                         v_k, v_c, v_lam, v_g, p_idx, p_target, p_k, p_c, p_lam,
                         t_idx, t_tri, t_bary, t_k, t_c, t_lam)
    if pend >= 0:  # the last iteration's update
        _volume_apply(x, w, v_part[v_pstart[pend]:v_pstart[pend + 1]], v_g, pend_f, pend_moved)


@numba.njit(**PBD_NUMBA)
def _take_rows(src, rows, out):
    """``out[i] = src[rows[i]]`` for ``(n, 3)`` float arrays (``np.take`` at a tenth of the cost)."""
    for i in range(rows.shape[0]):
        r = rows[i]
        out[i, 0] = src[r, 0]
        out[i, 1] = src[r, 1]
        out[i, 2] = src[r, 2]
    return out


@numba.njit(**PBD_NUMBA)
def _predict(x, v, prev, w, damp, h, gravity):
    """Store ``prev = x``; damp and integrate dynamic particles: ``x += h v``."""
    for i in range(x.shape[0]):
        px = x[i, 0]
        py = x[i, 1]
        pz = x[i, 2]
        prev[i, 0] = px
        prev[i, 1] = py
        prev[i, 2] = pz
        if w[i] > 0.0:
            vx = v[i, 0] * damp
            vy = v[i, 1] * damp - h * gravity
            vz = v[i, 2] * damp
            x[i, 0] = px + h * vx
            x[i, 1] = py + h * vy
            x[i, 2] = pz + h * vz


@numba.njit(**PBD_NUMBA)
def _velocities(x, v, prev, inv_h):
    for i in range(x.shape[0]):
        v[i, 0] = (x[i, 0] - prev[i, 0]) * inv_h
        v[i, 1] = (x[i, 1] - prev[i, 1]) * inv_h
        v[i, 2] = (x[i, 2] - prev[i, 2]) * inv_h


@numba.njit(**PBD_NUMBA)
def _begin_step(x_in, v_in, x_out, v_out, kin, kin_start):
    """Start a step: ``kin_start (q, 3)`` = the kinematic particles' positions in ``x_in``, and
    ``x_out``/``v_out`` = ``x_in``/``v_in`` unless they are the same arrays (stepping in place)."""
    n = x_in.shape[0]
    for q in range(kin.shape[0]):
        for d in range(3):
            kin_start[q, d] = x_in[kin[q], d]
    if x_out.ctypes.data != x_in.ctypes.data:  # stepping in place (the usual case): no copy
        for i in range(n):
            for d in range(3):
                x_out[i, d] = x_in[i, d]
    if v_out.ctypes.data != v_in.ctypes.data:
        for i in range(n):
            for d in range(3):
                v_out[i, d] = v_in[i, d]


@numba.njit(**PBD_NUMBA)
def _drive_kinematic(x, kin, kin_start, kin_target, s, substeps):
    """Substep ``s`` of ``substeps``: the kinematic particles ``kin`` go the fraction
    ``(s + 1) / substeps`` of the way from ``kin_start`` to ``kin_target (q, 3)``, and the last
    substep puts them exactly on the target."""
    alpha = (s + 1.0) / substeps
    for q in range(kin.shape[0]):
        i = kin[q]
        for d in range(3):
            if s == substeps - 1:  # exactly the control, no rounding
                x[i, d] = kin_target[q, d]
            else:
                x[i, d] = kin_start[q, d] + alpha * (kin_target[q, d] - kin_start[q, d])


@numba.njit(**PBD_NUMBA)
def _lam_offsets(d_idx, b_idx, a_idx, v_rest, p_idx):
    """Ends of the distance, bending, area, volume and position multipliers in the flat ``lams``
    (the attachment ones follow the last)."""
    o1 = d_idx.shape[0]
    o2 = o1 + b_idx.shape[0]
    o3 = o2 + a_idx.shape[0]
    o4 = o3 + v_rest.shape[0]
    return o1, o2, o3, o4, o4 + p_idx.shape[0]


@numba.njit(**PBD_NUMBA)
def _begin_substep(x, v, prev, w, damp, h, gravity, kin, kin_start, kin_target, s, substeps, xpbd, lams):
    """Everything of substep ``s`` before the projection: predict (:func:`_predict`), drive the
    kinematic particles (:func:`_drive_kinematic`) and, for XPBD, zero the multipliers."""
    _predict(x, v, prev, w, damp, h, gravity)
    _drive_kinematic(x, kin, kin_start, kin_target, s, substeps)
    if xpbd:  # the PBD modes never read the multipliers
        lams[:] = 0.0


@numba.njit(**PBD_NUMBA)
def _step(x_in, v_in, x_out, v_out, kin_target, p_target, h, threaded,
          w, kin, kin_start, prev, gravity, damp,
          substeps, iterations, xpbd, blocks, seg, lams,
          d_idx, d_rest, d_k, d_c, d_coef, d_runs, d_coef_t, d_wt,
          b_idx, b_rest, b_k, b_c, b_runs, b_w, b_rest_t, q_stretch, q_area, q_area_stop,
          a_idx, a_rest, a_k, a_c, a_runs, a_w, bufs,
          v_pstart, v_part, v_pcuts, v_cuts, v_tris, v_rstart, v_ref, v_rest, v_k, v_c, v_g,
          p_idx, p_k, p_c,
          t_idx, t_tri, t_bary, t_k, t_c):
    """A whole step of ``substeps`` substeps of length ``h``; ``x_out``/``v_out`` may be the
    inputs (the same array: then they are not copied onto themselves) or share no memory.

    The arguments that change from step to step come first (states, controls, ``h``,
    ``threaded``); the rest are the solver's frozen arrays, passed as one prepared tuple.

    ``seg (k + 2,)``: the block rows of each part and of the seam (:func:`_project_parts`);
    ``threaded``: unused here (:func:`_step_parts` projects the parts on threads; the same
    arguments, so the solver calls either);
    ``bufs (k, BATCH_ROWS * BATCH)``: the vectorised sweeps' scratch, one row per part.

    ``lams`` is one flat scratch array holding the multipliers of all kinds in the
    order distance, bending, area, volume, position, attachment.
    """
    _begin_step(x_in, v_in, x_out, v_out, kin, kin_start)
    o1, o2, o3, o4, o5 = _lam_offsets(d_idx, b_idx, a_idx, v_rest, p_idx)
    for s in range(substeps):
        _begin_substep(x_out, v_out, prev, w, damp, h, gravity, kin, kin_start, kin_target, s, substeps,
                       xpbd, lams)
        _project(x_out, w, blocks, iterations, xpbd,
                 d_idx, d_rest, d_k, d_c, lams[:o1], d_coef, d_runs, d_coef_t, d_wt,
                 b_idx, b_rest, b_k, b_c, lams[o1:o2], b_runs, b_w, b_rest_t, q_stretch,
                 q_area, q_area_stop,
                 a_idx, a_rest, a_k, a_c, lams[o2:o3], a_runs, a_w, bufs[0],
                 v_pstart, v_part, v_pcuts, v_cuts, v_tris, v_rstart, v_ref, v_rest, v_k, v_c,
                 lams[o3:o4], v_g,
                 p_idx, p_target, p_k, p_c, lams[o4:o5],
                 t_idx, t_tri, t_bary, t_k, t_c, lams[o5:])
        _velocities(x_out, v_out, prev, 1.0 / h)


@numba.njit(**PBD_NUMBA)
def _step_parts(x_in, v_in, x_out, v_out, kin_target, p_target, h, threaded,
          w, kin, kin_start, prev, gravity, damp,
          substeps, iterations, xpbd, blocks, seg, lams,
          d_idx, d_rest, d_k, d_c, d_coef, d_runs, d_coef_t, d_wt,
          b_idx, b_rest, b_k, b_c, b_runs, b_w, b_rest_t, q_stretch, q_area, q_area_stop,
          a_idx, a_rest, a_k, a_c, a_runs, a_w, bufs,
          v_pstart, v_part, v_pcuts, v_cuts, v_tris, v_rstart, v_ref, v_rest, v_k, v_c, v_g,
          p_idx, p_k, p_c,
          t_idx, t_tri, t_bary, t_k, t_c):
    """:func:`_step` with the parts on numba's threads (:func:`_project_parts`; the same
    result). Two kernels rather than one with a branch, so that a run that never threads (one
    thread, or a model of one part) never compiles the parallel sweep: numba compiles every
    branch of a kernel, and the parallel one was ~55 % of a first animate's compile (issue 28).
    The body is :func:`_step`'s but for the projection call; keep the two alike."""
    _begin_step(x_in, v_in, x_out, v_out, kin, kin_start)
    o1, o2, o3, o4, o5 = _lam_offsets(d_idx, b_idx, a_idx, v_rest, p_idx)
    for s in range(substeps):
        _begin_substep(x_out, v_out, prev, w, damp, h, gravity, kin, kin_start, kin_target, s, substeps,
                       xpbd, lams)
        _project_parts(x_out, w, blocks, seg, iterations, xpbd,
                       d_idx, d_rest, d_k, d_c, lams[:o1], d_coef, d_runs, d_coef_t, d_wt,
                       b_idx, b_rest, b_k, b_c, lams[o1:o2], b_runs, b_w, b_rest_t,
                       q_stretch, q_area, q_area_stop,
                       a_idx, a_rest, a_k, a_c, lams[o2:o3], a_runs, a_w, bufs,
                       v_pstart, v_part, v_pcuts, v_cuts, v_tris, v_rstart, v_ref, v_rest, v_k,
                       v_c, lams[o3:o4], v_g,
                       p_idx, p_target, p_k, p_c, lams[o4:o5],
                       t_idx, t_tri, t_bary, t_k, t_c, lams[o5:])
        _velocities(x_out, v_out, prev, 1.0 / h)
