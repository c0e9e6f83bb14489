"""The compiled half of the state pre-filter (:mod:`~baseplace.world.state_filter`): numba kernels only.

:func:`_uncertified_states` takes a batch of arm states (a whole joint line, issue 25 item 3) and,
state by state, places the robot's spheres by the arm's compiled chain
(:func:`~baseplace.robots.spheres._joint_frames`) and certifies each (robot geometry, scene part)
pair and each self pair free where a distance bound clears it: the scene's point indexes
(:mod:`~baseplace.world.point_index`), convex parts by their planes, hulls, sphere covers, the self
pairs' distance tables and anchor fields. It stops at the first state with a pair left, which
:class:`~baseplace.world.state_filter.StateFilter` hands to coal. Everything here reads arrays that
the filter's setup packed; nothing here allocates more than per-call scratch space.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from baseplace.robots.spheres import _joint_frames, _place, _place_one
from baseplace.world.point_index import _cell_range, _lower_bound, _seek, _within


@nb.njit(cache=True)
def _arm_centres(q, placements, axes, kinds, joint, local, out):
    """Sphere centres (G, 3) in the arm's base frame: ``local`` in the frame of arm joint ``joint`` (-1: fixed)."""
    F = np.empty((q.shape[0], 3, 4))
    R, t = np.empty((3, 3)), np.empty(3)
    _joint_frames(q, placements, axes, kinds, F, R, t)
    _place(joint, local, F, out)


@nb.njit(cache=True)
def _transformed(C, T, out):
    """Points C (G, 3) moved by the rigid transform T (4, 4), into ``out``."""
    for k in range(C.shape[0]):
        for a in range(3):
            out[k, a] = T[a, 0] * C[k, 0] + T[a, 1] * C[k, 1] + T[a, 2] * C[k, 2] + T[a, 3]


@nb.njit(cache=True)
def _points_rows(out_i, r0, r1, rows, reach, W, radius, Ws, sub_start, sub_radius, joint, Wj, group_radius,
                 i, stamp, sub_joint, sub_local, F, T, Cs, points, keys, starts, lo, hi, cell, dims, field, field_lo, field_h,
                 hull_start, hull_planes):  # fmt: skip
    """Scene rows r0..r1 (sorted by arm joint) against one part's box centres: ``out_i[p]`` True where not certified.

    The box centres are a :class:`PointIndex`'s arrays; ``reach`` holds the boxes' half diagonal.
    The geometries an arm joint moves are certified together when the sphere around them all
    (``Wj``, ``group_radius``) is clear by the index's distance bound; else a geometry with a
    cover by its bounding sphere's distance bound alone or every cover sphere's exact query,
    one without by its bounding sphere's exact query; failing those, when every box centre within
    its bounding sphere's reach lies that far outside one of its hull's face planes
    (:func:`_points_outside_hull`).
    """
    group, group_bound = -2, 0.0
    if len(points) == 0:
        out_i[r0:r1] = False
        return False
    any_row = False
    for p in range(r0, r1):
        g = rows[p]
        if joint[g] != group:
            group = joint[g]
            group_bound = _lower_bound(Wj[group], lo, hi, field, field_lo, field_h)
        if group_bound > group_radius[group] + reach[p]:  # each row's own reach: a group's rows may differ
            out_i[p] = False
            continue
        covered = sub_start[g + 1] - sub_start[g] > 1
        r = radius[g] + reach[p]
        touch = _lower_bound(W[g], lo, hi, field, field_lo, field_h) <= r
        if touch and not covered:
            touch = _within(W[g], r, True, points, keys, starts, lo, cell, dims) >= 0.0
        elif touch:
            touch = False
            _cover_placed(g, i, stamp, sub_start, sub_joint, sub_local, F, T, Cs, Ws)
            for s in range(sub_start[g], sub_start[g + 1]):
                r = sub_radius[s] + reach[p]
                if _lower_bound(Ws[s], lo, hi, field, field_lo, field_h) <= r and (
                    _within(Ws[s], r, True, points, keys, starts, lo, cell, dims) >= 0.0
                ):
                    touch = True
                    break
        if touch:
            touch = not _points_outside_hull(g, W[g], radius[g] + reach[p], reach[p], joint, F, T, hull_start,
                                             hull_planes, points, keys, starts, lo, cell, dims)  # fmt: skip
        out_i[p] = touch
        any_row |= touch
    return any_row


@nb.njit(cache=True)
def _points_outside_hull(g, c, r, reach, joint, F, T, hull_start, hull_planes, points, keys, starts, lo, cell, dims):  # fmt: skip
    """Whether every point within r of c (world frame, geometry g's bounding sphere) is more than ``reach`` from g's hull.

    Each such point, moved into the frame of the arm joint that moves g (``T``: the arm's base in
    the world; ``F``: the joints in the base), must lie farther than ``reach`` outside one of the
    hull's face planes (:func:`_outside_planes`); the cells of the index are walked as :func:`_within` walks them.
    """
    a, b = hull_start[g], hull_start[g + 1]
    if a == b:
        return False
    j, hint = joint[g], a
    local = np.empty(3)
    r2 = r * r
    i0, i1, j0, j1, k0, k1 = _cell_range(c, r + 1e-9, lo, cell, dims)
    u = 0  # every key before u is below the next row's first (:func:`~baseplace.world.point_index._seek`)
    for k in range(k0, k1 + 1):
        for jj in range(j0, j1 + 1):
            row = dims[0] * (jj + dims[1] * k)
            u = _seek(keys, u, row + i0)
            while u < len(keys) and keys[u] <= row + i1:
                for p in range(starts[u], starts[u + 1]):
                    dx, dy, dz = points[p, 0] - c[0], points[p, 1] - c[1], points[p, 2] - c[2]
                    if dx * dx + dy * dy + dz * dz > r2:
                        continue
                    dx, dy, dz = points[p, 0] - T[0, 3], points[p, 1] - T[1, 3], points[p, 2] - T[2, 3]
                    for m in range(3):  # into the arm's base frame: T^-1 p
                        local[m] = T[0, m] * dx + T[1, m] * dy + T[2, m] * dz
                    hint = _outside_planes(local, reach, j, F, hull_planes, a, b, hint)
                    if hint < 0:
                        return False
                u += 1
    return True


@nb.njit(cache=True, inline="always")
def _shape_touches(c, r, kind, a, b, planes, balls):
    """Whether the sphere (c (3,), r) is not certified clear of a convex part or a bounding ball.

    Kind 1: the hull planes a..b (inside <= 0); kind 2: the ball ``balls[a]`` (centre, radius).
    """
    if kind == 1:  # certified by the first plane the centre lies more than r outside
        for h in range(a, b):
            if planes[h, 0] * c[0] + planes[h, 1] * c[1] + planes[h, 2] * c[2] + planes[h, 3] > r:
                return False
        return True
    dx, dy, dz = c[0] - balls[a, 0], c[1] - balls[a, 1], c[2] - balls[a, 2]
    return not math.sqrt(dx * dx + dy * dy + dz * dz) > r + balls[a, 3]


@nb.njit(cache=True)
def _uncertified_states(Q, placements, axes, kinds, joint, local, radius, sub_start, sub_joint, sub_local,
                        sub_radius, group_local, group_radius, hull_start, hull_planes, vert_start, verts, T, scene_rows, scene_reach, parts, offs, all_points, all_keys, all_starts,
                        all_fields, geo, ints, halves, planes, balls, self_pairs, self_reach, self_runs, run_reach, self_table,
                        tab_joint, tab_lo, tab_step, tab_n, tab_rho, tab_off, tab_cert, anchor_of, anc_joint, anc_box, anc_lo,
                        anc_h, anc_dims, anc_off, anc_field, anc_reach, anc_group_reach, start, out):  # fmt: skip
    """Per state Q[i] (n,), which pairs its spheres do not certify free: ``out[i, p]`` (m, P + S) bool.

    The whole-edge check of issue 25 item 3: every state's spheres placed and tested in one call.
    Scene pairs ``p < P``: robot geometry ``scene_rows[p]``, grouped by scene part (``parts[q]``:
    kind, a, b, and the part's rows r0..r1; kind 0: box centres in the point index q packed by
    :func:`_packed` (``offs`` .. ``ints``),
    boxes ``halves[q]`` a half diagonal across (:func:`_points_rows`); kind 1, 2: :func:`_shape_touches`),
    certified when the geometry's bounding sphere or every sphere of its cover (``sub_*``) is
    clear by ``scene_reach[p]``; then the self pairs (S, 2), certified when the bounding spheres
    or their covers (:func:`_covers_near`) are farther apart than ``self_reach`` plus their radii, or
    the pair's distance table (``self_table[p]`` >= 0, :func:`_table_clear`) clears it. The self
    pairs come in runs of one geometry g against the geometries that one arm joint j moves
    (``self_runs`` (R, 4): g, j, the run's pairs r0..r1): a run is certified at once when g's
    bounding sphere is farther from j's group sphere than ``run_reach`` plus their radii. A self
    pair whose first geometry lies in an anchor field's set (``anchor_of[p]`` >= 0, or
    ``-2 - anchor`` where its table is asked instead; the ``anc_*`` arrays: :func:`_anchor_bound`) is certified with the whole set at once when the field's lower
    bound clears the second geometry's bounding sphere, or every sphere of its cover, by the
    largest reach of its pairs with the set (``anc_reach``); a run at once when it clears j's
    group sphere (``anc_group_reach``). Each answer is kept for the state.
    Goes from state ``start`` and stops at the first state with any pair left (coal decides it,
    then the call goes on from the next): returns its index, or -1 when every state is certified.
    """
    G, K, J = joint.shape[0], sub_joint.shape[0], group_local.shape[0]
    F = np.empty((Q.shape[1], 3, 4))
    group_joint = np.arange(J)
    Cj, Wj = np.empty((J, 3)), np.empty((J, 3))
    R, t = np.empty((3, 3)), np.empty(3)
    Cg, Cs = np.empty((G, 3)), np.empty((K, 3))
    W, Ws = np.empty((G, 3)), np.empty((K, 3))
    stamp = np.full(G, -1)  # the state each geometry's cover spheres were last placed for
    near_h = np.empty(K, dtype=np.bool_)
    # per self pair and hull (its first geometry's, its second's): the plane that last served
    hull_hint = np.full((self_pairs.shape[0], 2), -1, dtype=np.int64)
    A = anc_joint.shape[0]
    anc_stamp, anc_clear = np.full((A, G), -1), np.zeros((A, G), dtype=np.bool_)  # per anchor and geometry
    anc_gstamp, anc_gclear = (
        np.full((A, J), -1),
        np.zeros((A, J), dtype=np.bool_),
    )  # per anchor and joint group
    P = scene_rows.shape[0]
    reach = np.empty(P)
    part_reach = np.zeros(parts.shape[0])  # the largest of each part's rows
    for q in range(parts.shape[0]):
        reach[parts[q, 3] : parts[q, 4]] = scene_reach[parts[q, 3] : parts[q, 4]] + halves[q] * (
            parts[q, 0] == 0
        )
        for p in range(parts[q, 3], parts[q, 4]):
            part_reach[q] = max(part_reach[q], reach[p])
    for i in range(start, Q.shape[0]):
        _joint_frames(Q[i], placements, axes, kinds, F, R, t)
        _place(joint, local, F, Cg)
        _transformed(Cg, T, W)
        _place(group_joint, group_local, F, Cj)
        _transformed(Cj, T, Wj)
        out_i = out[i]
        any_pair = False
        for q in range(parts.shape[0]):
            kind, a, b, r0, r1 = parts[q, 0], parts[q, 1], parts[q, 2], parts[q, 3], parts[q, 4]
            if kind == 0 and _part_far(r0, r1, scene_rows, joint, Wj, group_radius, part_reach[q], geo[q]):
                out_i[r0:r1] = False  # every row's group sphere clear of the part's bounding box
                continue
            if kind == 0:
                pts = all_points[offs[q, 0] : offs[q + 1, 0]]
                keys = all_keys[offs[q, 1] : offs[q + 1, 1]]
                starts = all_starts[offs[q, 2] : offs[q + 1, 2]]
                field = all_fields[offs[q, 3] : offs[q + 1, 3]].reshape((ints[q, 3], ints[q, 4], ints[q, 5]))
                lo, hi, cell, field_lo, field_h = (
                    geo[q, 0:3],
                    geo[q, 3:6],
                    geo[q, 6],
                    geo[q, 7:10],
                    geo[q, 10],
                )
                dims = ints[q, 0:3]
                any_pair |= _points_rows(out_i, r0, r1, scene_rows, reach, W, radius, Ws, sub_start, sub_radius,
                                         joint, Wj, group_radius, i, stamp, sub_joint, sub_local, F, T, Cs, pts, keys, starts, lo, hi, cell, dims, field,
                                         field_lo, field_h, hull_start, hull_planes)  # fmt: skip
                continue
            group, group_clear = -2, False
            for p in range(r0, r1):
                g = scene_rows[p]
                if joint[g] != group:  # the rows of one arm joint together: its group sphere first
                    group = joint[g]
                    group_clear = not _shape_touches(Wj[group], group_radius[group] + part_reach[q], kind, a, b,
                                                     planes, balls)  # fmt: skip
                if group_clear:
                    out_i[p] = False
                    continue
                touch = _shape_touches(W[g], radius[g] + reach[p], kind, a, b, planes, balls)
                if touch and sub_start[g + 1] - sub_start[g] > 1:
                    touch = False
                    _cover_placed(g, i, stamp, sub_start, sub_joint, sub_local, F, T, Cs, Ws)
                    for s in range(sub_start[g], sub_start[g + 1]):
                        if _shape_touches(Ws[s], sub_radius[s] + reach[p], kind, a, b, planes, balls):
                            touch = True
                            break
                if touch and kind == 1:
                    touch = not _vertices_outside(
                        g, W[g], reach[p], joint, F, T, vert_start, verts, planes, a, b
                    )
                out_i[p] = touch
                any_pair |= touch
        for run in range(self_runs.shape[0]):
            g, j, r0, r1 = self_runs[run, 0], self_runs[run, 1], self_runs[run, 2], self_runs[run, 3]
            if not _near(Cg, g, Cj, j, radius[g] + group_radius[j] + run_reach[run]):
                out_i[P + r0 : P + r1] = False
                continue
            an = anchor_of[r0]  # one g, one j: every pair of the run in the same set (or none)
            if an >= 0:
                if anc_gstamp[an, j] != i:
                    anc_gstamp[an, j] = i
                    anc_gclear[an, j] = _anchor_bound(Cj[j], an, F, anc_joint, anc_box, anc_lo, anc_h, anc_dims, anc_off,
                                                     anc_field) > group_radius[j] + anc_group_reach[an, j]  # fmt: skip
                if anc_gclear[an, j]:
                    out_i[P + r0 : P + r1] = False
                    continue
            for p in range(r0, r1):
                g, h = self_pairs[p, 0], self_pairs[p, 1]
                touch = _near(Cg, g, Cg, h, radius[g] + radius[h] + self_reach[p])
                an = anchor_of[p]
                if touch and an >= 0:
                    if anc_stamp[an, h] != i:
                        anc_stamp[an, h] = i
                        anc_clear[an, h] = _anchor_clear(h, an, i, Cg, radius, stamp, sub_start, sub_joint, sub_local,
                                                        sub_radius, F, T, Cs, Ws, anc_joint, anc_box, anc_lo, anc_h,
                                                        anc_dims, anc_off, anc_field, anc_reach[an, h])  # fmt: skip
                    touch = not anc_clear[an, h]
                if touch and self_table[p] >= 0:
                    touch = not _table_clear(Q[i], self_table[p], tab_joint, tab_lo, tab_step, tab_n, tab_rho, tab_off,
                                             tab_cert)  # fmt: skip
                if touch:
                    touch = _covers_near(g, h, i, self_reach[p], Cg, radius, stamp, sub_start, sub_joint, sub_local,
                                         sub_radius, F, T, Cs, Ws, near_h)  # fmt: skip
                if touch:  # by g's hull, else h's; each tried first from the plane that served it last
                    k = _hull_clear(g, h, i, self_reach[p], joint, Cg, radius, stamp, sub_start, sub_joint, sub_local,
                                    sub_radius, F, T, Cs, Ws, hull_start, hull_planes, hull_hint[p, 0])  # fmt: skip
                    if k >= 0:
                        hull_hint[p, 0], touch = k, False
                    else:
                        k = _hull_clear(h, g, i, self_reach[p], joint, Cg, radius, stamp, sub_start, sub_joint,
                                        sub_local, sub_radius, F, T, Cs, Ws, hull_start, hull_planes, hull_hint[p, 1])  # fmt: skip
                        if k >= 0:
                            hull_hint[p, 1], touch = k, False
                out_i[P + p] = touch
                any_pair |= touch
        if any_pair:
            return i
    return -1


@nb.njit(cache=True, inline="always")
def _part_far(r0, r1, rows, joint, Wj, group_radius, reach, geo):
    """Whether the group sphere of every row r0..r1's arm joint is farther than ``reach`` from a point part's bounding box.

    ``geo[0:3]``, ``geo[3:6]``: the box (the lowest and highest box centre); ``reach`` at least
    every row's. :func:`_points_rows` certifies such rows by the same box distance (the first
    term of :func:`~baseplace.world.point_index._lower_bound`), so this early out changes no
    answer: it spares the part's array views and the call (about 1 us per part and state).
    """
    group = -2
    for p in range(r0, r1):
        j = joint[rows[p]]
        if j == group:
            continue
        group = j
        if j < 0:
            return False
        d2 = 0.0
        for k in range(3):
            c = Wj[j, k]
            if c < geo[k]:
                d2 += (geo[k] - c) ** 2
            elif c > geo[3 + k]:
                d2 += (c - geo[3 + k]) ** 2
        r = group_radius[j] + reach
        if not d2 > r * r:
            return False
    return True


@nb.njit(cache=True, inline="always")
def _box_d2(x, y, z, box):
    """The squared distance from the point (x, y, z) to the box (6,) (lo, hi)."""
    d2 = 0.0
    if x < box[0]:
        d2 += (box[0] - x) ** 2
    elif x > box[3]:
        d2 += (x - box[3]) ** 2
    if y < box[1]:
        d2 += (box[1] - y) ** 2
    elif y > box[4]:
        d2 += (y - box[4]) ** 2
    if z < box[2]:
        d2 += (box[2] - z) ** 2
    elif z > box[5]:
        d2 += (z - box[5]) ** 2
    return d2


@nb.njit(cache=True, inline="always")
def _anchor_bound(c, a, F, anc_joint, anc_box, anc_lo, anc_h, anc_dims, anc_off, anc_field):
    """A lower bound [m] of the distance from the point c (3,) (the arm's base frame) to anchor a's geometries.

    In the frame of arm joint ``anc_joint[a]`` (-1: the arm's base): the distance to the set's
    bounding box ``anc_box[a]``, or, if more, the field's value at the nearest node less the
    point's distance to that node (the field is a lower bound of a distance, which changes by at
    most as much as the point moves: :func:`_anchor_field`).
    """
    x, y, z = c[0], c[1], c[2]
    f = anc_joint[a]
    if f >= 0:  # into the joint's frame: R^T (c - t)
        dx, dy, dz = x - F[f, 0, 3], y - F[f, 1, 3], z - F[f, 2, 3]
        x = F[f, 0, 0] * dx + F[f, 1, 0] * dy + F[f, 2, 0] * dz
        y = F[f, 0, 1] * dx + F[f, 1, 1] * dy + F[f, 2, 1] * dz
        z = F[f, 0, 2] * dx + F[f, 1, 2] * dy + F[f, 2, 2] * dz
    d2 = _box_d2(x, y, z, anc_box[a])
    h = anc_h[a]
    n0, n1, n2 = anc_dims[a, 0], anc_dims[a, 1], anc_dims[a, 2]
    u0 = min(max(round((x - anc_lo[a, 0]) / h), 0), n0 - 1)
    u1 = min(max(round((y - anc_lo[a, 1]) / h), 0), n1 - 1)
    u2 = min(max(round((z - anc_lo[a, 2]) / h), 0), n2 - 1)
    ex, ey, ez = x - (anc_lo[a, 0] + u0 * h), y - (anc_lo[a, 1] + u1 * h), z - (anc_lo[a, 2] + u2 * h)
    v = anc_field[anc_off[a] + (u0 * n1 + u1) * n2 + u2] - math.sqrt(ex * ex + ey * ey + ez * ez)
    return max(math.sqrt(d2), v)


@nb.njit(cache=True)
def _anchor_clear(h, a, i, Cg, radius, stamp, sub_start, sub_joint, sub_local, sub_radius, F, T, Cs, Ws, anc_joint,
                  anc_box, anc_lo, anc_h, anc_dims, anc_off, anc_field, reach):  # fmt: skip
    """Whether geometry h at state i is farther than ``reach`` from every geometry of anchor a (:func:`_anchor_bound`).

    By its bounding sphere, else by every sphere of its cover.
    """
    if (
        _anchor_bound(Cg[h], a, F, anc_joint, anc_box, anc_lo, anc_h, anc_dims, anc_off, anc_field)
        > radius[h] + reach
    ):
        return True
    if sub_start[h + 1] - sub_start[h] <= 1:
        return False
    _cover_placed(h, i, stamp, sub_start, sub_joint, sub_local, F, T, Cs, Ws)
    for s in range(sub_start[h], sub_start[h + 1]):
        if not _anchor_bound(Cs[s], a, F, anc_joint, anc_box, anc_lo, anc_h, anc_dims, anc_off, anc_field) > (
            sub_radius[s] + reach
        ):
            return False
    return True


@nb.njit(cache=True)
def _anchor_field(plane_start, planes, boxes, lo, h, dims, cap, out):
    """Per grid node ``lo + h * (i, j, k)`` (``dims``), a lower bound [m] of its distance to a set of convex hulls, into ``out``.

    Per hull m (its face planes ``planes[plane_start[m]:plane_start[m + 1]]``, unit normal and
    offset, inside <= 0, and its bounding box ``boxes[m]``: lo, hi): the largest of the distance
    to the box and the node's signed distances to the planes (each plane bounds a half-space
    holding the hull, so the node is at least that far from it); the smallest over the hulls,
    cut at ``cap``. Each is a largest or smallest of functions that change by at most as much as
    the node moves, so the value at a node less a point's distance to it bounds the point's.
    """
    for i in range(dims[0]):
        x = lo[0] + i * h
        for j in range(dims[1]):
            y = lo[1] + j * h
            for k in range(dims[2]):
                z = lo[2] + k * h
                best = cap
                for m in range(boxes.shape[0]):
                    d = math.sqrt(_box_d2(x, y, z, boxes[m]))
                    if d >= best:
                        continue
                    for p in range(plane_start[m], plane_start[m + 1]):
                        d = max(d, planes[p, 0] * x + planes[p, 1] * y + planes[p, 2] * z + planes[p, 3])
                        if d >= best:
                            break
                    best = min(best, d)
                out[i, j, k] = best


@nb.njit(cache=True)
def _covers_near(
    g, h, i, reach, Cg, radius, stamp, sub_start, sub_joint, sub_local, sub_radius, F, T, Cs, Ws, near_h
):
    """Whether self pair (g, h) at state i is not certified by its covers: True when some piece may be within ``reach``.

    Geometry g is the union of its cover's pieces, each in its sphere, and so is h. A piece of g
    is clear of a piece of h when g's piece's sphere is clear of h's bounding sphere, or h's
    piece's sphere is clear of g's bounding sphere, or the two pieces' spheres are clear of each
    other; only the pairs of pieces near the other geometry's bounding sphere are compared.
    """
    _cover_placed(g, i, stamp, sub_start, sub_joint, sub_local, F, T, Cs, Ws)
    _cover_placed(h, i, stamp, sub_start, sub_joint, sub_local, F, T, Cs, Ws)
    any_h = False
    for u in range(sub_start[h], sub_start[h + 1]):
        near_h[u] = _near(Cs, u, Cg, g, sub_radius[u] + radius[g] + reach)
        any_h |= near_h[u]
    if not any_h:
        return False
    for s in range(sub_start[g], sub_start[g + 1]):
        if not _near(Cs, s, Cg, h, sub_radius[s] + radius[h] + reach):
            continue
        for u in range(sub_start[h], sub_start[h + 1]):
            if near_h[u] and _near(Cs, s, Cs, u, sub_radius[s] + sub_radius[u] + reach):
                return True
    return False


@nb.njit(cache=True)
def _hull_clear(g, h, i, reach, joint, Cg, radius, stamp, sub_start, sub_joint, sub_local, sub_radius, F, T, Cs, Ws,
                hull_start, hull_planes, hint):  # fmt: skip
    """A face plane of geometry g's convex hull that shows geometry h at state i farther than ``reach`` from it, or -1.

    g's hull faces (``hull_planes[hull_start[g]:hull_start[g + 1]]``, unit normal and offset in the
    frame of the arm joint that moves g, inside <= 0) each bound a half-space holding g, so a
    sphere whose centre lies more than its radius + ``reach`` outside any one of them is that far
    from g. h is clear when its bounding sphere is, or every sphere of its cover is (the plane
    returned: the one that served the last). Tighter than sphere against sphere where g is large
    and flat-sided (TIAGo's torso beside the arm). The planes are tried from ``hint`` on (the one
    that served this pair at an earlier state, or -1), which changes no answer, only how soon it comes.
    """
    a, b = hull_start[g], hull_start[g + 1]
    if a == b:
        return -1
    j = joint[g]
    k = _outside_planes(Cg[h], radius[h] + reach, j, F, hull_planes, a, b, hint)
    if k >= 0:
        return k
    if sub_start[h + 1] - sub_start[h] <= 1:
        return -1
    _cover_placed(h, i, stamp, sub_start, sub_joint, sub_local, F, T, Cs, Ws)
    k = hint
    for s in range(sub_start[h], sub_start[h + 1]):
        k = _outside_planes(Cs[s], sub_radius[s] + reach, j, F, hull_planes, a, b, max(k, a))
        if k < 0:
            return -1
    return k


@nb.njit(cache=True)
def _vertices_outside(g, c, reach, joint, F, T, vert_start, verts, planes, a, b):
    """Whether geometry g's hull points all lie more than ``reach`` outside one of the world planes a..b.

    The planes bound a convex part (inside <= 0), so such a plane keeps g's whole hull that far
    from it. Only the plane that g's bounding sphere's centre c (3,) (world) lies farthest outside
    is tried. The points (``verts[vert_start[g]:vert_start[g + 1]]``, in the frame of the arm
    joint that moves g) are placed by ``F`` and ``T`` (the arm's base in the world).
    """
    u0, u1 = vert_start[g], vert_start[g + 1]
    if u0 == u1 or a == b:
        return False
    h, best = a, -np.inf
    for k in range(a, b):
        d = planes[k, 0] * c[0] + planes[k, 1] * c[1] + planes[k, 2] * c[2] + planes[k, 3]
        if d > best:
            h, best = k, d
    j = joint[g]
    base = np.empty(3)
    for u in range(u0, u1):
        _place_one(j, verts[u], F, base)
        d = planes[h, 3]
        for m in range(3):
            d += planes[h, m] * (T[m, 0] * base[0] + T[m, 1] * base[1] + T[m, 2] * base[2] + T[m, 3])
        if not d > reach:
            return False
    return True


@nb.njit(cache=True, inline="always")
def _outside_planes(c, r, j, F, planes, a, b, hint):
    """The index of a plane among a..b of joint j's frame (-1: the arm's base) that the point c (3,) (base frame) lies more than r outside, or -1.

    The planes are tried from ``hint`` on (a plane that served a nearby point: the same face
    usually serves again), then from a.
    """
    x, y, z = c[0], c[1], c[2]
    if j >= 0:  # into the joint's frame: R^T (c - t)
        dx, dy, dz = x - F[j, 0, 3], y - F[j, 1, 3], z - F[j, 2, 3]
        x = F[j, 0, 0] * dx + F[j, 1, 0] * dy + F[j, 2, 0] * dz
        y = F[j, 0, 1] * dx + F[j, 1, 1] * dy + F[j, 2, 1] * dz
        z = F[j, 0, 2] * dx + F[j, 1, 2] * dy + F[j, 2, 2] * dz
    h0 = hint if a <= hint < b else a
    for n in range(b - a):
        k = h0 + n
        if k >= b:
            k -= b - a
        if planes[k, 0] * x + planes[k, 1] * y + planes[k, 2] * z + planes[k, 3] > r:
            return k
    return -1


@nb.njit(cache=True, inline="always")
def _cover_placed(g, i, stamp, sub_start, sub_joint, sub_local, F, T, Cs, Ws):
    """Place geometry g's cover spheres for state i (arm frame ``Cs``, world ``Ws``) unless they are."""
    if stamp[g] == i:
        return
    stamp[g] = i
    for s in range(sub_start[g], sub_start[g + 1]):
        _place_one(sub_joint[s], sub_local[s], F, Cs[s])
        for a in range(3):
            Ws[s, a] = T[a, 0] * Cs[s, 0] + T[a, 1] * Cs[s, 1] + T[a, 2] * Cs[s, 2] + T[a, 3]


@nb.njit(cache=True, inline="always")
def _table_clear(q, t, tab_joint, tab_lo, tab_step, tab_n, tab_rho, tab_off, tab_cert):
    """Whether self pair table t certifies arm state q (n,) free (:func:`_distance_table`).

    Coal's distance at the nearest grid node, less how far the two geometries can have moved
    relative to each other since (lever arm times joint change, per joint), is above the margin.
    """
    index, slack = 0, 0.0
    for d in range(2):
        j = tab_joint[t, d]
        if j < 0:
            continue
        u = min(max(round((q[j] - tab_lo[t, d]) / tab_step[t, d]), 0), tab_n[t, d] - 1)
        slack += tab_rho[t, d] * abs(q[j] - (tab_lo[t, d] + u * tab_step[t, d]))
        index = index * tab_n[t, d] + u
    return tab_cert[tab_off[t] + index] > slack


@nb.njit(cache=True, inline="always")
def _near(A, a, B, b, reach):
    """Whether A[a] and B[b] are not farther apart than ``reach``."""
    dx, dy, dz = A[a, 0] - B[b, 0], A[a, 1] - B[b, 1], A[a, 2] - B[b, 2]
    return dx * dx + dy * dy + dz * dz <= reach * reach


@nb.njit(cache=True)
def _transformed_poses(C, T, out):
    """Points C (G, 3) moved by each rigid transform T[s] (S, 4, 4), into ``out`` (S, G, 3) (:func:`_transformed`'s arithmetic)."""
    for s in range(T.shape[0]):
        for k in range(C.shape[0]):
            for a in range(3):
                out[s, k, a] = T[s, a, 0] * C[k, 0] + T[s, a, 1] * C[k, 1] + T[s, a, 2] * C[k, 2] + T[s, a, 3]
