"""Particle-disjoint groups of constraints, projected concurrently (optional).

With ``SolverSettings(partitions=k)``, ``k > 1``, the moving particles are split into k
*parts*, and every constraint whose moving particles all lie in one part belongs to that
part; a constraint that joins parts belongs to the *seam*. Each Gauss-Seidel iteration
then projects the k parts concurrently (one thread each), every part in block order, and
then the seam in block order. Parts share no moving particle, so projecting them at the
same time gives exactly what projecting them one after the other does: the result depends
on ``partitions``, never on how many threads run them (one thread gives the same bytes).
It is still a sequential Gauss-Seidel sweep, in yet another order (as colouring is): the
converged solution is the same, the rounding and the per-iteration progress differ.

Particles of inverse mass 0 are never moved by a projection, so any part may read them;
they belong to no part and join nothing, except in a volume body, which sums a gradient
for each of its particles into scratch: a body holding one is projected in the seam
(:func:`body_groups`).

How the parts are cut (:func:`particle_parts`): whole connected bodies when they balance
(the muscles of a layer: no seam at all), else slabs of the rest shape, bisected
recursively at the median of the work across whichever axis cuts the fewest constraints
(one skin: the seam is one ring of constraints around the cut), unless the model is too
small for that to pay (:data:`MIN_SLAB_CONSTRAINTS`).
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from faceforge.pbd.model import (
    AREA, ATTACHMENT, BENDING, DISTANCE, KIND_NAMES, POSITION, VOLUME, Model)

#: bodies are kept whole when the heaviest part then carries at most this much more than
#: its even share of the work; otherwise the particles are cut into slabs
BALANCE = 1.1

#: slabs cost a thread launch per iteration (2-6 us); a model with fewer constraints than this
#: per part (~7 ns each) stays in one part (the orbicularis oris' layer, 421 on MakeHuman)
MIN_SLAB_CONSTRAINTS = 2000


def constraint_particles(model: Model) -> dict[int, list[np.ndarray]]:
    """Per kind code, the particle ids of each constraint: a list of ``(m_kind,)`` columns
    (a volume constraint is one body: its particles are listed by :func:`body_particles`)."""
    m = model
    return {
        DISTANCE: list(m.distance_indices.T),
        BENDING: list(m.bending_indices.T),
        AREA: list(m.area_indices.T),
        POSITION: [m.position_indices],
        ATTACHMENT: [m.attachment_indices, *m.attachment_triangles.T],
    }


def body_particles(model: Model, j: int) -> np.ndarray:
    """Global particle ids of volume body ``j``."""
    s = model.volume_particle_start
    return model.volume_particles[s[j]:s[j + 1]]


def particle_work(model: Model) -> np.ndarray:
    """``(n,) float64``: how many projections touch each particle per iteration (a volume
    body counts once per particle), the load measure of :func:`particle_parts`."""
    n = model.particle_count
    work = np.zeros(n)
    for cols in constraint_particles(model).values():
        for col in cols:
            work += np.bincount(col, minlength=n)
    work += np.bincount(model.volume_particles, minlength=n)
    return work


def _components(model: Model, moving: np.ndarray) -> np.ndarray:
    """Connected components ``(n,) int`` of the moving particles under all constraints."""
    n = model.particle_count
    rows, cols = [], []
    for columns in constraint_particles(model).values():
        a = columns[0]
        for b in columns[1:]:      # a star per constraint joins all of its particles
            keep = moving[a] & moving[b]
            rows.append(a[keep])
            cols.append(b[keep])
    for j in range(model.volume_count):
        p = body_particles(model, j)
        p = p[moving[p]]
        rows.append(p[:-1])
        cols.append(p[1:])
    r = np.concatenate(rows) if rows else np.zeros(0, np.int64)
    c = np.concatenate(cols) if cols else np.zeros(0, np.int64)
    graph = coo_matrix((np.ones(len(r)), (r, c)), shape=(n, n))
    return connected_components(graph, directed=False)[1]


def _cut_count(columns: dict, left: np.ndarray, right: np.ndarray, n: int) -> int:
    """How many constraints have particles on both sides of a cut ``left | right``."""
    side = np.full(n, -1, dtype=np.int64)
    side[left] = 0
    side[right] = 1
    return sum(int(np.count_nonzero(constraint_groups(cols, side, 2) == 2))
               for cols in columns.values())


def _bisect(ids, points, work, columns, parts, first, out) -> None:
    """Cut ``ids`` into ``parts`` slabs numbered from ``first``: recursively, at the share of
    the work the two sides get, across whichever axis of their points cuts the fewest
    constraints."""
    if parts == 1 or len(ids) == 0:
        out[ids] = first
        return
    left = parts // 2
    best = None
    for axis in range(points.shape[1]):
        order = ids[np.argsort(points[ids, axis], kind="stable")]
        cum = np.cumsum(work[order])
        cut = int(np.searchsorted(cum, cum[-1] * left / parts, side="right"))
        cost = _cut_count(columns, order[:cut], order[cut:], len(points))
        if best is None or cost < best[0]:
            best = (cost, order, cut)
    _, order, cut = best
    _bisect(order[:cut], points, work, columns, left, first, out)
    _bisect(order[cut:], points, work, columns, parts - left, first + left, out)


def mirror_sides(model: Model, mirror: np.ndarray, parts: int) -> np.ndarray | None:
    """Two slabs cut at the mirror plane of a mirror-symmetric model, ``(n,) int64``: 0 and 1
    for the moving particles on either side, ``parts`` (2: the seam's label) for those on the
    plane (their own mirror partner), -1 for inverse mass 0; None when no pair is found.

    mirror : (n,) int, each particle's mirror partner. A cut through the particles on the
    plane puts each in one part, so a constraint from it to a left particle and its twin to
    the right one land one in a part and one in the seam, projected in different phases of the
    sweep (issue 25: MakeHuman's frontalis inner moved its two sides 7.8 % apart, 4.1 % with
    one part). With the plane's particles in the seam, every constraint touching them is, and
    the two parts are mirror images of each other.
    """
    mirror = np.asarray(mirror, dtype=np.int64)
    moving = model.inv_mass > 0
    d = model.rest_positions - model.rest_positions[mirror]
    length = np.linalg.norm(d, axis=1)
    if parts != 2 or not (length > 0).any():
        return None
    normal = d[int(np.argmax(length))] / length.max()
    side = d @ normal
    out = np.where(side > 0, 0, 1).astype(np.int64)
    out[mirror == np.arange(len(mirror))] = parts
    out[~moving] = -1
    return out


def particle_parts(model: Model, parts: int, mirror: np.ndarray | None = None) -> np.ndarray:
    """Part of every particle, ``(n,) int64`` in ``[0, parts)``, or -1 for particles of
    inverse mass 0 (see the module docstring for the rule). With ``mirror`` ((n,) int, each
    particle's partner of a mirror-symmetric model) a model cut into two slabs is cut at the
    plane, its particles on the plane labelled ``parts`` (the seam; :func:`mirror_sides`)."""
    n = model.particle_count
    moving = model.inv_mass > 0
    out = np.full(n, -1, dtype=np.int64)
    ids = np.flatnonzero(moving)
    if parts <= 1 or len(ids) == 0:
        out[ids] = 0
        return out
    work = particle_work(model) + 1.0    # + 1: the particle's own predict and velocity update
    comp = _components(model, moving)[ids]
    comp_work = np.bincount(comp, weights=work[ids])
    load = np.zeros(parts)
    owner = np.zeros(len(comp_work), dtype=np.int64)
    for c in np.argsort(-comp_work, kind="stable"):   # largest first, to the lightest part
        owner[c] = int(np.argmin(load))
        load[owner[c]] += comp_work[c]
    if load.max() <= BALANCE * load.sum() / parts:
        out[ids] = owner[comp]
    elif model.constraint_count < MIN_SLAB_CONSTRAINTS * parts:
        out[ids] = 0
    elif mirror is not None and (sides := mirror_sides(model, mirror, parts)) is not None:
        out = sides
    else:
        _bisect(ids, model.rest_positions, work, constraint_particles(model), parts, 0, out)
    return out


def constraint_groups(columns: list[np.ndarray], part: np.ndarray, parts: int) -> np.ndarray:
    """Group of each constraint ``(m,) int64``: its moving particles' part, or ``parts`` (the
    seam) when they lie in several; a constraint with no moving particle goes to part 0.

    columns : the constraints' particle ids, one ``(m,)`` array per slot.
    """
    p = np.stack([part[c] for c in columns], axis=1) if columns else np.zeros((0, 1), np.int64)
    lo = np.where(p >= 0, p, parts).min(axis=1)
    hi = p.max(axis=1)
    group = np.where(hi < 0, 0, lo)
    return np.where((hi >= 0) & (lo != hi), parts, group).astype(np.int64)


def body_groups(model: Model, part: np.ndarray, parts: int) -> np.ndarray:
    """Group ``(b,) int64`` of each volume body, as :func:`constraint_groups`, except that a
    body holding a particle of inverse mass 0 goes to the seam: the volume projection sums a
    gradient into scratch rows of every particle of the body, so two bodies sharing such a
    particle in two parts would add into one row at the same time."""
    out = np.zeros(model.volume_count, dtype=np.int64)
    for j in range(model.volume_count):
        p = part[body_particles(model, j)]
        moving = np.unique(p[p >= 0])
        out[j] = parts if len(moving) > 1 or len(moving) < len(np.unique(p)) else (
            moving[0] if len(moving) else 0)
    return out


def split_blocks(blocks: np.ndarray, groups: dict[int, np.ndarray], parts: int):
    """Split each block into its groups' constraints, and order the rows part by part.

    blocks : (nb, 3) int rows (kind, start, stop); groups : per kind code, the ``(m,)``
    group of each of its constraints (``0..parts``, ``parts`` = the seam).
    Returns ``(perm, rows, segment)``: per kind code the permutation ``(m,) int64`` that
    makes each group of each block contiguous (a stable sort inside the block, so blocks
    keep their ranges); the new ``(nr, 3)`` rows, those of part 0 first (in block order),
    then part 1, ..., the seam last; and ``segment (nr,) int64``, the group of each row.
    """
    perm = {k: np.arange(len(g), dtype=np.int64) for k, g in groups.items()}
    cuts = []   # per block row: (kind, start, boundaries of its groups in the permuted order)
    for kind, start, stop in np.asarray(blocks, dtype=np.int64):
        g = groups[int(kind)][start:stop]
        order = np.argsort(g, kind="stable")
        perm[int(kind)][start:stop] = start + order
        bounds = start + np.searchsorted(g[order], np.arange(parts + 2))
        cuts.append((int(kind), bounds))
    rows, segment = [], []
    for s in range(parts + 1):
        for kind, bounds in cuts:
            if bounds[s + 1] > bounds[s]:
                rows.append((kind, bounds[s], bounds[s + 1]))
                segment.append(s)
    return (perm, np.array(rows, dtype=np.int64).reshape(-1, 3),
            np.array(segment, dtype=np.int64))


def _csr_take(start: np.ndarray, data: np.ndarray, order: np.ndarray):
    """Rows ``order`` of a CSR block ``(start (b+1,), data)``: ``(new_start, new_data)``."""
    pieces = [data[start[j]:start[j + 1]] for j in order]
    lengths = np.array([len(p) for p in pieces], dtype=np.int64)
    new_start = np.concatenate([[0], np.cumsum(lengths)]).astype(np.int64)
    return new_start, (np.concatenate(pieces) if pieces else data[:0].copy())


#: Model fields holding global particle ids (renumbered by :func:`partitioned`)
_PARTICLE_IDS = ("kinematic_indices", "distance_indices", "bending_indices", "area_indices",
                 "volume_triangles", "volume_particles", "position_indices",
                 "attachment_indices", "attachment_triangles")


def partitioned(model: Model, parts: int, mirror: np.ndarray | None = None):
    """``model`` renumbered and regrouped part by part (see the module docstring); ``mirror``
    ((n,) int, optional): each particle's mirror partner (:func:`particle_parts`).

    The particles are renumbered so that each part's are contiguous (in their old order,
    parts in order, particles of inverse mass 0 last): two threads then never write to one
    cache line (with the parts interleaved in memory, the two-part skin of the benchmark
    head ran 1.5x slower). The constraints of each block are grouped by part.

    Returns a :class:`Partition`.
    """
    part = particle_parts(model, parts, mirror)
    columns = constraint_particles(model)
    groups = {k: constraint_groups(cols, part, parts) for k, cols in columns.items()}
    groups[VOLUME] = body_groups(model, part, parts)
    perm, rows, segment = split_blocks(model.blocks, groups, parts)
    m = model
    changes = {"blocks": rows}
    for kind, names in ((DISTANCE, ("indices", "rest_length", "stiffness", "weight")),
                        (BENDING, ("indices", "rest_angle", "stiffness")),
                        (AREA, ("indices", "rest_area", "stiffness")),
                        (POSITION, ("indices", "rest_target", "stiffness")),
                        (ATTACHMENT, ("indices", "triangles", "bary", "stiffness"))):
        prefix = KIND_NAMES[kind]
        for name in names:
            changes[f"{prefix}_{name}"] = getattr(m, f"{prefix}_{name}")[perm[kind]]
    order = perm[VOLUME]
    changes["volume_rest_volume"] = m.volume_rest_volume[order]
    changes["volume_stiffness"] = m.volume_stiffness[order]
    for start, data in (("volume_triangle_start", "volume_triangles"),
                        ("volume_particle_start", "volume_particles"),
                        ("volume_reference_start", "volume_reference")):
        changes[start], changes[data] = _csr_take(getattr(m, start), getattr(m, data), order)
    _, changes["volume_local_triangles"] = _csr_take(m.volume_triangle_start,
                                                     m.volume_local_triangles, order)
    particle_order = np.argsort(np.where(part < 0, parts, part), kind="stable").astype(np.int64)
    new_id = np.empty_like(particle_order)
    new_id[particle_order] = np.arange(len(particle_order))
    for name in _PARTICLE_IDS:
        changes[name] = new_id[changes.get(name, getattr(m, name))]
    changes["rest_positions"] = m.rest_positions[particle_order]
    changes["inv_mass"] = m.inv_mass[particle_order]
    return Partition(dataclasses.replace(m, **changes), segment, particle_order,
                     perm[POSITION], part[particle_order])


@dataclasses.dataclass(frozen=True)
class Partition:
    """A model renumbered and regrouped by :func:`partitioned`.

    model : the new Model (``blocks`` are the rows of :func:`split_blocks`: part 0's first,
        the seam's last); segment : (nr,) int64, the group of each of its block rows;
    particle_order : (n,) int64, the old id of each new particle (``positions[particle_order]``
        are the new model's); position_order : (m_pos,) int64, the old slot of each position
        constraint (``Control.position_targets[position_order]`` are the new model's targets);
    part : (n,) int64, the part of each new particle (-1: inverse mass 0).
    """

    model: Model
    segment: np.ndarray
    particle_order: np.ndarray
    position_order: np.ndarray
    part: np.ndarray


def row_cuts(rows: np.ndarray, part: np.ndarray, parts: int):
    """Group the rows ``(f, k) int`` of particle ids (-1 = none) by part, the seam last.

    Returns ``(order (f,) int64, cuts (parts + 2,) int64)``: ``rows[order][cuts[p]:cuts[p + 1]]``
    are part ``p``'s (``p == parts``: the rows joining parts), in their old order.
    """
    rows = np.asarray(rows, dtype=np.int64)
    # index -1 (no particle) reads the appended -1; a row with a particle of inverse mass 0
    # (part -1) joins the seam, as in body_groups
    labels = np.append(np.where(part < 0, parts, part), -1)
    group = constraint_groups(list(rows.T), labels, parts)
    order = np.argsort(group, kind="stable").astype(np.int64)
    return order, np.searchsorted(group[order], np.arange(parts + 2)).astype(np.int64)
