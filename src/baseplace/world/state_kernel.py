"""The compiled half of the state pre-filter (:mod:`~baseplace.world.state_filter`): numba kernels only.

:func:`_uncertified_states` takes a batch of arm states (a whole joint line, issue 25 item 3) and,
state by state, places the robot's spheres by the arm's compiled chain
(:func:`~baseplace.robots.spheres._joint_frames`) and certifies each (robot geometry, scene part)
pair and each self pair free where a distance bound clears it: the scene's point indexes
(:mod:`~baseplace.world.point_index`), convex parts by their planes, hulls, sphere covers, the self
pairs' distance tables and anchor fields. It stops at the first state with a pair left, which
:class:`~baseplace.world.state_filter.StateFilter` hands to coal. Everything here reads arrays that
the filter's setup packed; nothing here allocates more than per-call scratch space.

:func:`_uncertified_line` checks the states of one joint line without asking every pair at every
state: a pair certified by a distance bound keeps the margin while its geometries move less than
the gap, so along a line whose every point's move is bounded (the lever arms) most pairs are asked
at few states (conservative advancement). Both run the one state check of :func:`_uncertified`.

:func:`_touch_proven` is the other direction: a state's scene pairs left over proven touching by
balls inside the robot's geometries, so that coal need not be asked.
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
def _points_rows(out_i, slack, ask, rows, reach, W, radius, Ws, sub_start, sub_radius, joint, Wj,
                 group_radius, i, stamp, sub_joint, sub_local, F, T, Cs, points, keys, starts, lo, hi, cell, dims,
                 field, field_lo, field_h, hull_start, hull_planes):  # fmt: skip
    """Scene rows ``ask`` (one part's, sorted by arm joint) against the part's box centres: ``out_i[p]`` True where not certified.

    The box centres are a :class:`PointIndex`'s arrays; ``reach`` holds the boxes' half diagonal.
    The geometries an arm joint moves are certified together when the sphere around them all
    (``Wj``, ``group_radius``) is clear by the index's distance bound; else a geometry with a
    cover by its bounding sphere's distance bound alone or every cover sphere's exact query,
    one without by its bounding sphere's exact query; failing those, when every box centre within
    its bounding sphere's reach lies that far outside one of its hull's face planes
    (:func:`_points_outside_hull`). A row certified by a distance bound gets by how much it clears
    its reach in ``slack`` (0 for the other certificates, and where it is left).
    """
    group, group_bound = -2, 0.0
    if len(points) == 0:
        for p in ask:
            out_i[p], slack[p] = False, np.inf  # nothing to touch
        return False
    any_row = False
    for p in ask:
        g = rows[p]
        if joint[g] != group:
            group = joint[g]
            group_bound = _lower_bound(Wj[group], lo, hi, field, field_lo, field_h)
        if group_bound > group_radius[group] + reach[p]:  # each row's own reach: a group's rows may differ
            out_i[p], slack[p] = False, group_bound - (group_radius[group] + reach[p])
            continue
        covered = sub_start[g + 1] - sub_start[g] > 1
        r = radius[g] + reach[p]
        bound = _lower_bound(W[g], lo, hi, field, field_lo, field_h)
        touch, gap = bound <= r, bound - r
        if touch and not covered:
            touch, gap = _within(W[g], r, True, points, keys, starts, lo, cell, dims) >= 0.0, 0.0
        elif touch:
            touch, gap = False, np.inf
            _cover_placed(g, i, stamp, sub_start, sub_joint, sub_local, F, T, Cs, Ws)
            for s in range(sub_start[g], sub_start[g + 1]):
                r = sub_radius[s] + reach[p]
                bound = _lower_bound(Ws[s], lo, hi, field, field_lo, field_h)
                if bound > r:
                    gap = min(gap, bound - r)
                    continue
                gap = 0.0  # an exact query: no distance
                if _within(Ws[s], r, True, points, keys, starts, lo, cell, dims) >= 0.0:
                    touch = True
                    break
        if touch:
            touch = not _points_outside_hull(g, W[g], radius[g] + reach[p], reach[p], joint, F, T, hull_start,
                                             hull_planes, points, keys, starts, lo, cell, dims)  # fmt: skip
            gap = 0.0
        out_i[p], slack[p] = touch, 0.0 if touch else max(gap, 0.0)
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
                    hint, _ = _outside_planes(local, reach, j, F, hull_planes, a, b, hint)
                    if hint < 0:
                        return False
                u += 1
    return True


@nb.njit(cache=True, inline="always")
def _shape_gap(c, r, kind, a, b, planes, balls, gaps):
    """By how much [m] the sphere (c (3,), r) is certified clear of a convex part or a bounding ball; -1 when it is not.

    Kind 1: the hull planes a..b (inside <= 0), certified when the centre lies more than r outside
    one (the gap: how much more, at the plane it lies farthest outside with ``gaps``, else at the
    first); kind 2: the ball ``balls[a]`` (centre, radius).
    """
    if kind == 1:
        best = -np.inf
        for h in range(a, b):
            best = max(best, planes[h, 0] * c[0] + planes[h, 1] * c[1] + planes[h, 2] * c[2] + planes[h, 3])
            if best > r and not gaps:
                break
        return best - r if best > r else -1.0
    dx, dy, dz = c[0] - balls[a, 0], c[1] - balls[a, 1], c[2] - balls[a, 2]
    d, reach = math.sqrt(dx * dx + dy * dy + dz * dz), r + balls[a, 3]
    return max(d - reach, 0.0) if d > reach else -1.0


@nb.njit(cache=True)
def _workspace(n, G, K, J, S, A, parts, scene_reach, halves, self_runs):
    """Scratch arrays of :func:`_uncertified`, for an arm of n joints (see there), each scene row's reach, each self pair's run."""
    P = scene_reach.shape[0]
    pair_run = np.empty(S, dtype=np.int64)
    for run in range(self_runs.shape[0]):
        pair_run[self_runs[run, 2] : self_runs[run, 3]] = run
    reach = np.empty(P)
    part_reach = np.zeros(parts.shape[0])  # the largest of each part's rows
    for q in range(parts.shape[0]):
        reach[parts[q, 3] : parts[q, 4]] = scene_reach[parts[q, 3] : parts[q, 4]] + halves[q] * (
            parts[q, 0] == 0
        )
        for p in range(parts[q, 3], parts[q, 4]):
            part_reach[q] = max(part_reach[q], reach[p])
    return (
        np.empty((n, 3, 4)),  # F: the arm joints' frames
        np.arange(J),  # the joint groups' joints
        np.empty((J, 3)),  # Cj, Wj: the joint groups' sphere centres, arm base and world
        np.empty((J, 3)),
        np.empty((3, 3)),
        np.empty(3),
        np.empty((G, 3)),  # Cg, Cs, W, Ws: the geometries' and cover spheres' centres
        np.empty((K, 3)),
        np.empty((G, 3)),
        np.empty((K, 3)),
        np.full(G, -1),  # the state each geometry's cover spheres were last placed for
        # per cover sphere, its gap to the other geometry's bounding sphere (:func:`_covers_gap`)
        np.empty(K),
        np.full((S, 2), -1, dtype=np.int64),  # per self pair and hull: the plane that last served
        np.full((A, G), -1),  # per anchor and geometry: the state last asked, the gap (-1: not clear)
        np.full((A, G), -1.0),
        np.full((A, J), -1),  # per anchor and joint group: the state last asked, the gap (-1: not clear)
        np.full((A, J), -1.0),
        reach,
        part_reach,
        pair_run,
    )


@nb.njit(cache=True)
def _uncertified(Q, a, b, n, travel, levers, placements, axes, kinds, joint, local, radius, sub_start, sub_joint,
                 sub_local, sub_radius, group_local, group_radius, hull_start, hull_planes, vert_start, verts, T,
                 scene_rows, scene_reach, parts, offs, all_points, all_keys, all_starts, all_fields, geo, ints, halves,
                 planes, balls, self_pairs, self_reach, self_runs, run_reach, self_table, tab_joint, tab_lo, tab_step,
                 tab_n, tab_rho, tab_off, tab_cert, anchor_of, anc_joint, anc_box, anc_lo, anc_h, anc_dims, anc_off,
                 anc_field, anc_reach, anc_group_reach, line_slack, queue, pool, ctl, start, out):  # fmt: skip
    """The one state check of :func:`_uncertified_states` (n = 0: the states ``Q[start:]``) and :func:`_uncertified_line` (n > 0: the line a -> b).

    Per state, which of the pairs asked (``ask``, sorted) are left (``out_i``) and, on a line, by
    how much [m] a distance bound certifies each clear of its margin (its gap: ``slack_i``; 0:
    certified otherwise, or not at all). ``i`` numbers the state for the covers' and anchors'
    caches. The arguments are those of the two, with dummies for the other's. Both pass the same
    types, no literal constant among them (numba compiles a callee anew for each literal value: a
    literal 0 for ``n`` or ``start`` compiled this body twice, about 30 s of a cold start).
    """
    ws = _workspace(a.shape[0], joint.shape[0], sub_joint.shape[0], group_local.shape[0], self_pairs.shape[0],
                    anc_joint.shape[0], parts, scene_reach, halves, self_runs)  # fmt: skip
    F, group_joint, Cj, Wj, R, t, Cg, Cs, W, Ws, stamp, gap_h, hull_hint, anc_stamp, anc_gap, anc_gstamp, anc_ggap, \
        reach, part_reach, pair_run = ws  # fmt: skip
    P, M = scene_rows.shape[0], out.shape[1]
    line = n > 0
    ask_all = np.arange(M)
    dense_slack = np.empty(M)
    left = np.zeros(M if line else 0, dtype=np.bool_)  # a line's state's pairs left
    q = np.empty(a.shape[0])
    step = np.empty(M if line else 0)  # per pair, how far its geometries move against each other per step
    if line:
        G, N = joint.shape[0], a.shape[0]
        # per geometry, how far the arm joints up to each move its points per step
        moves = np.zeros((G, N + 1))
        for g in range(G):
            for d in range(N):
                moves[g, d + 1] = moves[g, d] + abs(b[d] - a[d]) * levers[g, d] / n
        for p in range(P):
            step[p] = min(moves[scene_rows[p], N], travel / n)
        # a self pair: only the joints between the two geometries move one against the other
        for p in range(self_pairs.shape[0]):
            g, h = self_pairs[p, 0], self_pairs[p, 1]
            if joint[g] > joint[h]:
                g, h = h, g
            step[P + p] = moves[h, joint[h] + 1] - moves[h, joint[g] + 1]
    k, i, seg_i, seg_j, c0, c, phase = start - 1, 0, 0, 0, 0, 0, 0
    while True:
        if not line:  # the next state of Q
            k += 1
            if k >= Q.shape[0]:
                return -1
            q_k, ask, gaps, slack_i, out_i, i = Q[k], ask_all, False, dense_slack, out[k], k
        else:
            phase = ctl[3]
            if phase < 2:  # state 0 (its gaps only), then state n, every pair asked
                if phase == 0:
                    pool[:M] = ask_all
                    ctl[4] = M
                k, ask = phase * n, pool[:M]
            else:  # the next segment with a pair whose gaps at its ends do not cover it: its midpoint
                k = -1
                while ctl[0] < ctl[1]:
                    seg_i, seg_j = queue[ctl[0], 0], queue[ctl[0], 1]
                    s0, s1 = queue[ctl[0], 2], queue[ctl[0], 2] + queue[ctl[0], 3]
                    ctl[0] += 1
                    if seg_j - seg_i < 2:
                        continue
                    c0 = c = ctl[4]
                    for v in range(s0, s1):
                        p = pool[v]
                        if not line_slack[seg_i, p] + line_slack[seg_j, p] > (seg_j - seg_i) * step[p]:
                            pool[c] = p
                            c += 1
                    if c > c0:
                        ctl[4] = c
                        k = (seg_i + seg_j) // 2
                        break
                if k < 0:
                    return -1
                ask = pool[c0:c]
            for d in range(a.shape[0]):
                q[d] = a[d] + (b[d] - a[d]) * (k / n)
            q_k, gaps, slack_i, out_i, i = q, True, line_slack[k], left, ctl[2]
        m = ask.shape[0]
        if m == out_i.shape[0]:  # every pair asked
            out_i[:] = False
            if gaps:
                slack_i[:] = 0.0
        else:
            for p in ask:
                out_i[p], slack_i[p] = False, 0.0
        _joint_frames(q_k, placements, axes, kinds, F, R, t)
        _place(joint, local, F, Cg)
        _transformed(Cg, T, W)
        _place(group_joint, group_local, F, Cj)
        _transformed(Cj, T, Wj)
        any_pair = False
        u = 0
        for q_ in range(parts.shape[0]):
            kind, pa, pb, r0, r1 = parts[q_, 0], parts[q_, 1], parts[q_, 2], parts[q_, 3], parts[q_, 4]
            u0 = u
            u = _past(ask, u, r0, r1, 0)
            if u == u0:
                continue
            rows_q = ask[u0:u]
            if kind == 0 and _part_far(rows_q, scene_rows, joint, Wj, group_radius, reach, geo[q_], slack_i):
                continue  # every asked row's group sphere clear of the part's bounding box
            if kind == 0:
                pts = all_points[offs[q_, 0] : offs[q_ + 1, 0]]
                keys = all_keys[offs[q_, 1] : offs[q_ + 1, 1]]
                starts = all_starts[offs[q_, 2] : offs[q_ + 1, 2]]
                field = all_fields[offs[q_, 3] : offs[q_ + 1, 3]].reshape(
                    (ints[q_, 3], ints[q_, 4], ints[q_, 5])
                )
                lo, hi, cell, field_lo, field_h = (
                    geo[q_, 0:3],
                    geo[q_, 3:6],
                    geo[q_, 6],
                    geo[q_, 7:10],
                    geo[q_, 10],
                )
                dims = ints[q_, 0:3]
                any_pair |= _points_rows(out_i, slack_i, rows_q, scene_rows, reach, W, radius, Ws, sub_start, sub_radius,
                                         joint, Wj, group_radius, i, stamp, sub_joint, sub_local, F, T, Cs, pts, keys,
                                         starts, lo, hi, cell, dims, field, field_lo, field_h, hull_start, hull_planes)  # fmt: skip
                continue
            group, group_gap = -2, -1.0
            for p in rows_q:
                g = scene_rows[p]
                if joint[g] != group:  # the rows of one arm joint together: its group sphere first
                    group = joint[g]
                    group_gap = _shape_gap(
                        Wj[group], group_radius[group] + part_reach[q_], kind, pa, pb, planes, balls, gaps
                    )
                if group_gap >= 0.0:
                    slack_i[p] = group_gap
                    continue
                gap = _shape_gap(W[g], radius[g] + reach[p], kind, pa, pb, planes, balls, gaps)
                touch = gap < 0.0
                if touch and sub_start[g + 1] - sub_start[g] > 1:
                    touch, gap = False, np.inf
                    _cover_placed(g, i, stamp, sub_start, sub_joint, sub_local, F, T, Cs, Ws)
                    for s in range(sub_start[g], sub_start[g + 1]):
                        sub_gap = _shape_gap(
                            Ws[s], sub_radius[s] + reach[p], kind, pa, pb, planes, balls, gaps
                        )
                        if sub_gap < 0.0:
                            touch = True
                            break
                        gap = min(gap, sub_gap)
                if touch and kind == 1:  # by the part's face planes, then its edges' (parts[q_, 5])
                    touch = not _vertices_outside(
                        g, W[g], radius[g], reach[p], joint, F, T, vert_start, verts, planes, pa, parts[q_, 5]
                    )
                    gap = 0.0
                out_i[p], slack_i[p] = touch, 0.0 if touch else gap
                any_pair |= touch
        while u < m:  # the self pairs asked, run by run
            run = pair_run[ask[u] - P]
            g, j, r0, r1 = self_runs[run, 0], self_runs[run, 1], self_runs[run, 2], self_runs[run, 3]
            u0 = u
            u = _past(ask, u, r0, r1, P)
            gap = _gap(Cg, g, Cj, j, radius[g] + group_radius[j] + run_reach[run])
            an = anchor_of[ask[u0] - P]  # one g, one j: every pair of the run in the same set (or none)
            if gap < 0.0 and an >= 0:
                if anc_gstamp[an, j] != i:
                    anc_gstamp[an, j] = i
                    bound = _anchor_bound(
                        Cj[j], an, F, anc_joint, anc_box, anc_lo, anc_h, anc_dims, anc_off, anc_field
                    )
                    reach_j = group_radius[j] + anc_group_reach[an, j]
                    anc_ggap[an, j] = bound - reach_j if bound > reach_j else -1.0
                gap = anc_ggap[an, j]
            if gap >= 0.0:
                if gaps:
                    for v in range(u0, u):
                        slack_i[ask[v]] = gap
                continue
            for v in range(u0, u):
                p = ask[v] - P
                g, h = self_pairs[p, 0], self_pairs[p, 1]
                gap = _gap(Cg, g, Cg, h, radius[g] + radius[h] + self_reach[p])
                touch = gap < 0.0
                an = anchor_of[p]
                if touch and an >= 0:
                    if anc_stamp[an, h] != i:
                        anc_stamp[an, h] = i
                        anc_gap[an, h] = _anchor_gap(h, an, i, Cg, radius, stamp, sub_start, sub_joint, sub_local,
                                                     sub_radius, F, T, Cs, Ws, anc_joint, anc_box, anc_lo, anc_h,
                                                     anc_dims, anc_off, anc_field, anc_reach[an, h])  # fmt: skip
                    gap = anc_gap[an, h]
                    touch = gap < 0.0
                if touch and self_table[p] >= 0:
                    gap = _table_gap(
                        q_k, self_table[p], tab_joint, tab_lo, tab_step, tab_n, tab_rho, tab_off, tab_cert
                    )
                    touch = gap < 0.0
                if touch:
                    gap = _covers_gap(g, h, i, self_reach[p], Cg, radius, stamp, sub_start, sub_joint, sub_local,
                                      sub_radius, F, T, Cs, Ws, gap_h)  # fmt: skip
                    touch = gap < 0.0
                if touch:  # by g's hull, else h's; each tried first from the plane that served it last
                    kh, gap = _hull_clear(g, h, i, self_reach[p], joint, Cg, radius, stamp, sub_start, sub_joint,
                                         sub_local, sub_radius, F, T, Cs, Ws, hull_start, hull_planes, hull_hint[p, 0])  # fmt: skip
                    if kh >= 0:
                        hull_hint[p, 0], touch = kh, False
                    else:
                        kh, gap = _hull_clear(h, g, i, self_reach[p], joint, Cg, radius, stamp, sub_start, sub_joint,
                                             sub_local, sub_radius, F, T, Cs, Ws, hull_start, hull_planes, hull_hint[p, 1])  # fmt: skip
                        if kh >= 0:
                            hull_hint[p, 1], touch = kh, False
                if touch:  # every hull point of h outside a face plane of g's hull, else the other way
                    kh, gap = _hull_points_clear(g, h, self_reach[p], joint, Cg, F, hull_start, hull_planes, vert_start,
                                                 verts, hull_hint[p, 0])  # fmt: skip
                    if kh >= 0:
                        hull_hint[p, 0], touch = kh, False
                    else:
                        kh, gap = _hull_points_clear(h, g, self_reach[p], joint, Cg, F, hull_start, hull_planes,
                                                     vert_start, verts, hull_hint[p, 1])  # fmt: skip
                        if kh >= 0:
                            hull_hint[p, 1], touch = kh, False
                out_i[ask[v]], slack_i[ask[v]] = touch, max(gap, 0.0)
                any_pair |= touch
        if not line:
            if any_pair:
                return k
            continue
        ctl[2] += 1
        if phase == 0:
            ctl[3] = 1
            continue
        if phase == 1:
            ctl[3] = 2
            queue[0, 0], queue[0, 1], queue[0, 2], queue[0, 3] = 0, n, 0, M
            ctl[0], ctl[1] = 0, 1
        else:
            for e in range(2):
                queue[ctl[1], 0], queue[ctl[1], 1] = (seg_i, k) if e == 0 else (k, seg_j)
                queue[ctl[1], 2], queue[ctl[1], 3] = c0, c - c0
                ctl[1] += 1
        if any_pair:
            out[0, :] = False
            for p in ask:
                out[0, p] = left[p]
            return k


@nb.njit(cache=True)
def _uncertified_states(Q, placements, axes, kinds, joint, local, radius, sub_start, sub_joint, sub_local,
                        sub_radius, group_local, group_radius, hull_start, hull_planes, vert_start, verts, T, scene_rows, scene_reach, parts, offs, all_points, all_keys, all_starts,
                        all_fields, geo, ints, halves, planes, balls, self_pairs, self_reach, self_runs, run_reach, self_table,
                        tab_joint, tab_lo, tab_step, tab_n, tab_rho, tab_off, tab_cert, anchor_of, anc_joint, anc_box, anc_lo,
                        anc_h, anc_dims, anc_off, anc_field, anc_reach, anc_group_reach, start, out):  # fmt: skip
    """Per state Q[i] (n,), which pairs its spheres do not certify free: ``out[i, p]`` (m, P + S) bool.

    Every state's spheres placed and tested in one call (:func:`_uncertified`). Scene pairs ``p < P``:
    robot geometry ``scene_rows[p]``, grouped by scene part (``parts[q]``: kind, a, b, the part's
    rows r0..r1 and, for kind 1, where its edges' planes end (they follow its faces' a..b); kind 0:
    box centres in the point index q packed by :func:`_packed` (``offs`` .. ``ints``),
    boxes ``halves[q]`` a half diagonal across (:func:`_points_rows`); kind 1, 2: :func:`_shape_gap`),
    certified when the geometry's bounding sphere or every sphere of its cover (``sub_*``) is
    clear by ``scene_reach[p]``; then the self pairs (S, 2), certified when the bounding spheres
    or their covers (:func:`_covers_gap`) are farther apart than ``self_reach`` plus their radii, or
    the pair's distance table (``self_table[p]`` >= 0, :func:`_table_gap`) clears it. The self
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
    z = np.zeros(Q.shape[1])
    n = Q.shape[0] - Q.shape[0]  # 0, typed int64 as in _uncertified_line's call (see _uncertified's note)
    return _uncertified(Q, z, z, n, 0.0, np.zeros((joint.shape[0], Q.shape[1])), placements, axes, kinds, joint, local,
                        radius, sub_start, sub_joint, sub_local, sub_radius, group_local, group_radius, hull_start,
                        hull_planes, vert_start, verts, T, scene_rows, scene_reach, parts, offs, all_points, all_keys,
                        all_starts, all_fields, geo, ints, halves, planes, balls, self_pairs, self_reach, self_runs,
                        run_reach, self_table, tab_joint, tab_lo, tab_step, tab_n, tab_rho, tab_off, tab_cert, anchor_of,
                        anc_joint, anc_box, anc_lo, anc_h, anc_dims, anc_off, anc_field, anc_reach, anc_group_reach,
                        np.zeros((1, out.shape[1])), np.zeros((1, 4), dtype=np.int64), np.zeros(1, dtype=np.int64),
                        np.zeros(5, dtype=np.int64), start, out)  # fmt: skip


@nb.njit(cache=True)
def _uncertified_poses(Q, T_all, placements, axes, kinds, joint, local, radius, sub_start, sub_joint, sub_local,
                       sub_radius, group_local, group_radius, hull_start, hull_planes, vert_start, verts, scene_rows,
                       scene_reach, parts, offs, all_points, all_keys, all_starts, all_fields, geo, ints, halves, planes,
                       balls, self_pairs, self_reach, self_runs, run_reach, self_table, tab_joint, tab_lo, tab_step, tab_n,
                       tab_rho, tab_off, tab_cert, anchor_of, anc_joint, anc_box, anc_lo, anc_h, anc_dims, anc_off,
                       anc_field, anc_reach, anc_group_reach, start, out):  # fmt: skip
    """:func:`_uncertified_states` for states each at its own pose: Q[s] (n,) with the arm's base at ``T_all[s]`` (4, 4).

    From state ``start`` on, the first with a pair left (its pairs in ``out[s]``), or -1: the
    robustness score's error draws in one call instead of one per draw
    (:meth:`~baseplace.world.state_filter.StateFilter.colliding_poses`).
    """
    first = start - start  # 0, not a literal (see _uncertified's note)
    for s in range(start, Q.shape[0]):
        k = _uncertified_states(Q[s : s + 1], placements, axes, kinds, joint, local, radius, sub_start, sub_joint,
                                sub_local, sub_radius, group_local, group_radius, hull_start, hull_planes, vert_start,
                                verts, T_all[s], scene_rows, scene_reach, parts, offs, all_points, all_keys, all_starts,
                                all_fields, geo, ints, halves, planes, balls, self_pairs, self_reach, self_runs, run_reach,
                                self_table, tab_joint, tab_lo, tab_step, tab_n, tab_rho, tab_off, tab_cert, anchor_of,
                                anc_joint, anc_box, anc_lo, anc_h, anc_dims, anc_off, anc_field, anc_reach,
                                anc_group_reach, first, out[s : s + 1])  # fmt: skip
        if k >= 0:
            return s
    return -1


@nb.njit(cache=True)
def _uncertified_line(a, b, n, travel, levers, placements, axes, kinds, joint, local, radius, sub_start, sub_joint, sub_local,
                      sub_radius, group_local, group_radius, hull_start, hull_planes, vert_start, verts, T, scene_rows, scene_reach, parts, offs, all_points, all_keys, all_starts,
                      all_fields, geo, ints, halves, planes, balls, self_pairs, self_reach, self_runs, run_reach, self_table,
                      tab_joint, tab_lo, tab_step, tab_n, tab_rho, tab_off, tab_cert, anchor_of, anc_joint, anc_box, anc_lo,
                      anc_h, anc_dims, anc_off, anc_field, anc_reach, anc_group_reach, slack, queue, pool, ctl, out):  # fmt: skip
    """The states ``a + k / n (b - a)``, k = 1..n, of a joint line (n,): the next one with pairs left, or -1.

    :func:`_uncertified_states`' verdict on every state of the line, without asking each pair at
    each state. A point of robot geometry g moves at most ``levers[g] @ |b - a|`` [m] along the
    whole line (``levers`` (G, n): per unit change of each arm joint, :func:`geometry_levers`), and
    at most ``travel`` (a bound for the whole robot); so by that over n per step. Against another
    robot geometry it moves only by the arm joints between the two (the arm is a chain: the joints
    before both move them together). A pair certified at state k with a gap s (``slack[k]``,
    :func:`_uncertified`) keeps its distance above the margin while its geometries move less than s
    (against each other, for a self pair). The line is cut by bisection, far end first (state 0
    is asked too, for its gaps only): a pair is asked at a segment's midpoint only when its gaps
    at the segment's two ends do not add up to its move along the segment, for then it is
    certified at every point of the segment (conservative advancement, as in Schwarzer, Saha and
    Latombe 2005's adaptive edge checks); a segment one step long is not cut (its two ends are the
    resolution, as in :func:`_uncertified_states`).
    Every state asked with a pair left goes back to the caller (its pairs in ``out[0]``), which
    decides it (coal) and calls again: ``slack`` (n + 1, P + S), ``queue`` (2 n + 2, 4: a
    segment's ends and the pairs its parent asked, in ``pool``, at least (n + 1) (P + S) long),
    and ``ctl`` (5,: queue head and tail, states asked, 0 before the first call, pool used) keep
    the place. A pair left to coal at a state has no gap there.
    """
    return _uncertified(np.zeros((0, a.shape[0])), a, b, n, travel, levers, placements, axes, kinds, joint, local,
                        radius, sub_start, sub_joint, sub_local, sub_radius, group_local, group_radius, hull_start,
                        hull_planes, vert_start, verts, T, scene_rows, scene_reach, parts, offs, all_points, all_keys,
                        all_starts, all_fields, geo, ints, halves, planes, balls, self_pairs, self_reach, self_runs,
                        run_reach, self_table, tab_joint, tab_lo, tab_step, tab_n, tab_rho, tab_off, tab_cert, anchor_of,
                        anc_joint, anc_box, anc_lo, anc_h, anc_dims, anc_off, anc_field, anc_reach, anc_group_reach,
                        slack, queue, pool, ctl, n - n, out)  # fmt: skip


@nb.njit(cache=True, inline="always")
def _past(ask, u, r0, r1, offset):
    """The first index from u of the sorted pairs ``ask`` at or past ``offset + r1``; ``ask[u]`` is not below ``offset + r0``.

    At once when ``ask`` holds all of r0..r1 (every pair asked), else step by step.
    """
    v = u + r1 - r0
    if v <= ask.shape[0] and ask[v - 1] == offset + r1 - 1:
        return v
    while u < ask.shape[0] and ask[u] < offset + r1:
        u += 1
    return u


@nb.njit(cache=True, inline="always")
def _part_far(ask, rows, joint, Wj, group_radius, reach, geo, slack):
    """Whether the group sphere of every row in ``ask``'s arm joint is farther than its reach from a point part's bounding box.

    ``geo[0:6]``: the box (the lowest and highest box centre). :func:`_points_rows` certifies
    such rows by the same box distance (the first term of
    :func:`~baseplace.world.point_index._lower_bound`), so this early out changes no answer: it
    spares the part's array views and the call (about 1 us per part and state). Each row's gap
    goes into ``slack`` as it is found (:func:`_points_rows` writes them all again when this does
    not hold).
    """
    group, d = -2, 0.0
    for p in ask:
        j = joint[rows[p]]
        if j < 0:
            return False
        if j != group:
            group = j
            d = math.sqrt(_box_d2(Wj[j, 0], Wj[j, 1], Wj[j, 2], geo))
        reach_p = group_radius[j] + reach[p]
        if not d > reach_p:
            return False
        slack[p] = d - reach_p
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
    x, y, z = _in_joint_frame(c, anc_joint[a], F)
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
def _anchor_gap(h, a, i, Cg, radius, stamp, sub_start, sub_joint, sub_local, sub_radius, F, T, Cs, Ws, anc_joint,
                anc_box, anc_lo, anc_h, anc_dims, anc_off, anc_field, reach):  # fmt: skip
    """By how much [m] geometry h at state i is farther than ``reach`` from every geometry of anchor a (:func:`_anchor_bound`); -1 when it is not shown to be.

    By its bounding sphere, else by every sphere of its cover (the least of theirs).
    """
    bound = _anchor_bound(Cg[h], a, F, anc_joint, anc_box, anc_lo, anc_h, anc_dims, anc_off, anc_field)
    if bound > radius[h] + reach:
        return bound - (radius[h] + reach)
    if sub_start[h + 1] - sub_start[h] <= 1:
        return -1.0
    _cover_placed(h, i, stamp, sub_start, sub_joint, sub_local, F, T, Cs, Ws)
    gap = np.inf
    for s in range(sub_start[h], sub_start[h + 1]):
        bound = _anchor_bound(Cs[s], a, F, anc_joint, anc_box, anc_lo, anc_h, anc_dims, anc_off, anc_field)
        if not bound > sub_radius[s] + reach:
            return -1.0
        gap = min(gap, bound - (sub_radius[s] + reach))
    return gap


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
def _covers_gap(
    g, h, i, reach, Cg, radius, stamp, sub_start, sub_joint, sub_local, sub_radius, F, T, Cs, Ws, gap_h
):
    """By how much [m] self pair (g, h) at state i is certified farther apart than ``reach`` by its covers; -1 when it is not.

    Geometry g is the union of its cover's pieces, each in its sphere, and so is h. A piece of g
    is clear of a piece of h when g's piece's sphere is clear of h's bounding sphere, or h's
    piece's sphere is clear of g's bounding sphere, or the two pieces' spheres are clear of each
    other; only the pairs of pieces near the other geometry's bounding sphere are compared. The
    gap: the least over the pairs of pieces, each by the test that cleared it.
    """
    _cover_placed(g, i, stamp, sub_start, sub_joint, sub_local, F, T, Cs, Ws)
    _cover_placed(h, i, stamp, sub_start, sub_joint, sub_local, F, T, Cs, Ws)
    any_h, best = False, np.inf
    for u in range(sub_start[h], sub_start[h + 1]):
        gap_h[u] = _gap(Cs, u, Cg, g, sub_radius[u] + radius[g] + reach)
        any_h |= gap_h[u] < 0.0
    if not any_h:
        for u in range(sub_start[h], sub_start[h + 1]):
            best = min(best, gap_h[u])
        return best
    for s in range(sub_start[g], sub_start[g + 1]):
        e = _gap(Cs, s, Cg, h, sub_radius[s] + radius[h] + reach)
        if e >= 0.0:
            best = min(best, e)
            continue
        for u in range(sub_start[h], sub_start[h + 1]):
            e = gap_h[u]
            if e < 0.0:
                e = _gap(Cs, s, Cs, u, sub_radius[s] + sub_radius[u] + reach)
                if e < 0.0:
                    return -1.0
            best = min(best, e)
    return best


@nb.njit(cache=True)
def _hull_clear(g, h, i, reach, joint, Cg, radius, stamp, sub_start, sub_joint, sub_local, sub_radius, F, T, Cs, Ws,
                hull_start, hull_planes, hint):  # fmt: skip
    """A face plane of geometry g's convex hull that shows geometry h at state i farther than ``reach`` from it, and by how much [m]; or (-1, -1).

    g's hull faces (``hull_planes[hull_start[g]:hull_start[g + 1]]``, unit normal and offset in the
    frame of the arm joint that moves g, inside <= 0) each bound a half-space holding g, so a
    sphere whose centre lies more than its radius + ``reach`` outside any one of them is that far
    from g. h is clear when its bounding sphere is, or every sphere of its cover is (the plane
    returned: the one that served the last; the gap: the least). Tighter than sphere against
    sphere where g is large and flat-sided (TIAGo's torso beside the arm). The planes are tried
    from ``hint`` on (the one that served this pair at an earlier state, or -1), which changes no
    answer, only how soon it comes.
    """
    a, b = hull_start[g], hull_start[g + 1]
    if a == b:
        return -1, -1.0
    j = joint[g]
    k, gap = _outside_planes(Cg[h], radius[h] + reach, j, F, hull_planes, a, b, hint)
    if k >= 0:
        return k, gap
    if sub_start[h + 1] - sub_start[h] <= 1:
        return -1, -1.0
    _cover_placed(h, i, stamp, sub_start, sub_joint, sub_local, F, T, Cs, Ws)
    k, gap = hint, np.inf
    for s in range(sub_start[h], sub_start[h + 1]):
        k, sub_gap = _outside_planes(Cs[s], sub_radius[s] + reach, j, F, hull_planes, a, b, max(k, a))
        if k < 0:
            return -1, -1.0
        gap = min(gap, sub_gap)
    return k, gap


@nb.njit(cache=True)
def _hull_points_clear(g, h, reach, joint, Cg, F, hull_start, hull_planes, vert_start, verts, hint):
    """A face plane of geometry g's convex hull with every point h's hull is made of more than ``reach`` outside it, and the least margin [m]; or (-1, -1).

    The exact form of :func:`_hull_clear`'s test: h's hull points (``verts[vert_start[h]:vert_start[h + 1]]``,
    in the frame of the arm joint that moves h) instead of the spheres around them, so a pair a
    few millimetres apart is certified where every sphere of h's cover reaches past the gap
    (TIAGo's arm tucked beside the torso's column, about 2 cm away: the column's face planes
    separate it). The plane holds g on its inner side and h's hull beyond ``reach`` on the
    other, so the margin is a lower bound of the hulls' distance less ``reach``. Two planes are
    tried: ``hint`` (the one that served this pair last, or -1), then the one that h's bounding
    sphere's centre (``Cg[h]``, the arm's base frame) lies farthest outside; each is moved into
    h's joint frame (``F``: the arm joints' frames in the arm's base) and h's points are tested
    against it, stopping at the first within ``reach``.
    """
    a, b = hull_start[g], hull_start[g + 1]
    u0, u1 = vert_start[h], vert_start[h + 1]
    if a == b or u0 == u1:
        return -1, -1.0
    jg, jh = joint[g], joint[h]
    R = np.empty((3, 4))  # h's joint frame in g's: R[:, :3] x + R[:, 3], once for both planes
    for r in range(3):
        for c in range(4):
            R[r, c] = _frame_entry(jg, jh, F, r, c)
    if a <= hint < b:
        gap = _points_beyond(hint, R, hull_planes, verts, u0, u1, reach)
        if gap > 0.0:
            return hint, gap
    x, y, z = _in_joint_frame(Cg[h], jg, F)
    k, best = a, -np.inf
    for m in range(a, b):
        v = hull_planes[m, 0] * x + hull_planes[m, 1] * y + hull_planes[m, 2] * z + hull_planes[m, 3]
        if v > best:
            k, best = m, v
    if k == hint:
        return -1, -1.0
    gap = _points_beyond(k, R, hull_planes, verts, u0, u1, reach)
    return (k, gap) if gap > 0.0 else (-1, -1.0)


@nb.njit(cache=True, inline="always")
def _points_beyond(k, R, hull_planes, verts, u0, u1, reach):
    """The least margin [m] by which the points ``verts[u0:u1]`` lie more than ``reach`` outside plane k, moved by ``R`` (3, 4) into the plane's frame; -1 when one does not."""
    nx = hull_planes[k, 0] * R[0, 0] + hull_planes[k, 1] * R[1, 0] + hull_planes[k, 2] * R[2, 0]
    ny = hull_planes[k, 0] * R[0, 1] + hull_planes[k, 1] * R[1, 1] + hull_planes[k, 2] * R[2, 1]
    nz = hull_planes[k, 0] * R[0, 2] + hull_planes[k, 1] * R[1, 2] + hull_planes[k, 2] * R[2, 2]
    d = (
        hull_planes[k, 0] * R[0, 3]
        + hull_planes[k, 1] * R[1, 3]
        + hull_planes[k, 2] * R[2, 3]
        + hull_planes[k, 3]
        - reach
    )
    gap = np.inf
    for u in range(u0, u1):
        v = nx * verts[u, 0] + ny * verts[u, 1] + nz * verts[u, 2] + d
        if not v > 0.0:
            return -1.0
        gap = min(gap, v)
    return gap


@nb.njit(cache=True, inline="always")
def _frame_entry(jg, jh, F, r, c):
    """Entry (r, c) of the 3 x 4 transform from arm joint jh's frame into jg's (``F``; -1: the arm's base)."""
    if jg < 0:
        if jh < 0:
            return 1.0 if r == c else 0.0
        return F[jh, r, c]
    if jh < 0:  # F[jg]^-1: R^T, -R^T t
        if c < 3:
            return F[jg, c, r]
        return -(F[jg, 0, r] * F[jg, 0, 3] + F[jg, 1, r] * F[jg, 1, 3] + F[jg, 2, r] * F[jg, 2, 3])
    v = 0.0  # R_g^T (R_h x + t_h - t_g)
    if c < 3:
        for e in range(3):
            v += F[jg, e, r] * F[jh, e, c]
        return v
    for e in range(3):
        v += F[jg, e, r] * (F[jh, e, 3] - F[jg, e, 3])
    return v


@nb.njit(cache=True)
def _vertices_outside(g, c, r, reach, joint, F, T, vert_start, verts, planes, a, b):
    """Whether geometry g's hull points all lie more than ``reach`` outside one of the world planes a..b.

    The planes bound a convex part (inside <= 0), so such a plane keeps g's whole hull that far
    from it. The plane that g's bounding sphere (centre c (3,), world; radius r) lies farthest
    outside is tried first, then the others the sphere reaches beyond ``reach`` (no hull point
    lies farther out than the sphere). The points (``verts[vert_start[g]:vert_start[g + 1]]``, in
    the frame of the arm joint that moves g) are placed by ``F`` and ``T`` (the arm's base in the world).
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
    world = np.empty((u1 - u0, 3))
    for u in range(u0, u1):
        _place_one(j, verts[u], F, base)
        for m in range(3):
            world[u - u0, m] = T[m, 0] * base[0] + T[m, 1] * base[1] + T[m, 2] * base[2] + T[m, 3]
    for n in range(b - a + 1):
        k = h if n == 0 else a + n - 1
        if n > 0 and (
            k == h
            or not planes[k, 0] * c[0] + planes[k, 1] * c[1] + planes[k, 2] * c[2] + planes[k, 3] + r > reach
        ):
            continue
        outside = True
        for u in range(u1 - u0):
            d = (
                planes[k, 0] * world[u, 0]
                + planes[k, 1] * world[u, 1]
                + planes[k, 2] * world[u, 2]
                + planes[k, 3]
            )
            if not d > reach:
                outside = False
                break
        if outside:
            return True
    return False


@nb.njit(cache=True, inline="always")
def _outside_planes(c, r, j, F, planes, a, b, hint):
    """A plane among a..b of joint j's frame (-1: the arm's base) that the point c (3,) (base frame) lies more than r outside, and by how much more [m]; or (-1, -1).

    The planes are tried from ``hint`` on (a plane that served a nearby point: the same face
    usually serves again), then from a.
    """
    x, y, z = _in_joint_frame(c, j, F)
    h0 = hint if a <= hint < b else a
    for n in range(b - a):
        k = h0 + n
        if k >= b:
            k -= b - a
        v = planes[k, 0] * x + planes[k, 1] * y + planes[k, 2] * z + planes[k, 3]
        if v > r:
            return k, v - r
    return -1, -1.0


@nb.njit(cache=True, inline="always")
def _in_joint_frame(c, j, F):
    """The point c (3,) of the arm's base frame in the frame of arm joint j (``F[j]``; -1: the arm's base itself)."""
    x, y, z = c[0], c[1], c[2]
    if j >= 0:  # R^T (c - t)
        dx, dy, dz = x - F[j, 0, 3], y - F[j, 1, 3], z - F[j, 2, 3]
        x = F[j, 0, 0] * dx + F[j, 1, 0] * dy + F[j, 2, 0] * dz
        y = F[j, 0, 1] * dx + F[j, 1, 1] * dy + F[j, 2, 1] * dz
        z = F[j, 0, 2] * dx + F[j, 1, 2] * dy + F[j, 2, 2] * dz
    return x, y, z


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
def _table_gap(q, t, tab_joint, tab_lo, tab_step, tab_n, tab_rho, tab_off, tab_cert):
    """By how much [m] self pair table t certifies arm state q (n,) free (:func:`_distance_table`), or -1 when it does not.

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
    cert = tab_cert[tab_off[t] + index]
    return cert - slack if cert > slack else -1.0


@nb.njit(cache=True, inline="always")
def _gap(A, a, B, b, reach):
    """By how much [m] A[a] and B[b] are farther apart than ``reach`` (>= 0), or -1 when they are not."""
    dx, dy, dz = A[a, 0] - B[b, 0], A[a, 1] - B[b, 1], A[a, 2] - B[b, 2]
    d2 = dx * dx + dy * dy + dz * dz
    if d2 <= reach * reach:
        return -1.0
    return max(math.sqrt(d2) - reach, 0.0)


@nb.njit(cache=True)
def _transformed_poses(C, T, out):
    """Points C (G, 3) moved by each rigid transform T[s] (S, 4, 4), into ``out`` (S, G, 3) (:func:`_transformed`'s arithmetic)."""
    for s in range(T.shape[0]):
        for k in range(C.shape[0]):
            for a in range(3):
                out[s, k, a] = T[s, a, 0] * C[k, 0] + T[s, a, 1] * C[k, 1] + T[s, a, 2] * C[k, 2] + T[s, a, 3]


@nb.njit(cache=True)
def _touch_proven(q, placements, axes, kinds, joint, T, left, scene_rows, limit, parts, offs, all_points, all_keys,
                  all_starts, geo, ints, box_half, planes, ball_start, ball_local, ball_radius):  # fmt: skip
    """Whether a ball inside a robot geometry proves one of the scene pairs ``left`` (P,) touching at arm state q (n,).

    Coal's verdict on those pairs is then True without asking coal: a pair touches when its
    geometries come closer than its margin, and a ball (centre, radius) that lies within a robot
    geometry (:func:`~baseplace.world.state_filter.contact_balls`, ``ball_*`` per geometry, placed
    by the arm's chain and ``T``, the arm's base in the world) and whose centre is closer to the
    scene part than ``limit[p]`` (the margin less a depth for rounding) plus its radius brings the
    geometry that close (a point's distance bounds the geometry's; a ball inside the part by a
    depth must move that depth plus its radius to leave it). The centre's signed distance is exact
    against an OcTree part's boxes (kind 0, ``box_half[q]`` the half side of every box, 0 where
    they are not all one size: not asked) and, inside it, against a convex part's planes (kind 1;
    outside, the planes bound it from below only); a part of kind 2 (only its bounding ball is
    known) is not asked. False says nothing: coal decides.
    """
    F = np.empty((q.shape[0], 3, 4))
    R, t = np.empty((3, 3)), np.empty(3)
    _joint_frames(q, placements, axes, kinds, F, R, t)
    x, w = np.empty(3), np.empty(3)
    for q_ in range(parts.shape[0]):
        kind, pa, pb, r0, r1 = parts[q_, 0], parts[q_, 1], parts[q_, 2], parts[q_, 3], parts[q_, 4]
        if kind == 2 or (kind == 0 and not box_half[q_] > 0.0):
            continue
        pts = all_points[offs[q_, 0] : offs[q_ + 1, 0]]
        keys = all_keys[offs[q_, 1] : offs[q_ + 1, 1]]
        starts = all_starts[offs[q_, 2] : offs[q_ + 1, 2]]
        lo, cell, dims = geo[q_, 0:3], geo[q_, 6], ints[q_, 0:3]
        for p in range(r0, r1):
            if not left[p]:
                continue
            g = scene_rows[p]
            for s in range(ball_start[g], ball_start[g + 1]):
                _place_one(joint[g], ball_local[s], F, x)
                for a in range(3):
                    w[a] = T[a, 0] * x[0] + T[a, 1] * x[1] + T[a, 2] * x[2] + T[a, 3]
                bound = limit[p] + ball_radius[s]
                if kind == 0:
                    if _box_closer(w, bound, box_half[q_], pts, keys, starts, lo, cell, dims):
                        return True
                    continue
                inside = -np.inf
                for h in range(pa, pb):
                    inside = max(
                        inside, planes[h, 0] * w[0] + planes[h, 1] * w[1] + planes[h, 2] * w[2] + planes[h, 3]
                    )
                if inside <= 0.0 and inside < bound:
                    return True
    return False


@nb.njit(cache=True)
def _box_closer(c, bound, h, points, keys, starts, lo, cell, dims):
    """Whether c (3,) has a signed distance below ``bound`` [m] to an axis-aligned cube of half side h centred at one of the points.

    Outside a cube the distance is exact (the norm of how far c lies beyond each face pair),
    inside it the negative depth (to the nearest face). The cubes' centres within ``bound`` plus
    their half diagonal are the candidates, walked as :func:`~baseplace.world.point_index._within` walks them.
    """
    e = bound + h * 1.7320508075688772
    if not e > 0.0 or len(points) == 0:
        return False
    i0, i1, j0, j1, k0, k1 = _cell_range(c, e + 1e-9, lo, cell, dims)
    u = 0
    for k in range(k0, k1 + 1):
        for jj in range(j0, j1 + 1):
            row = dims[0] * (jj + dims[1] * k)
            u = _seek(keys, u, row + i0)
            while u < len(keys) and keys[u] <= row + i1:
                for p in range(starts[u], starts[u + 1]):
                    dx, dy, dz = (
                        abs(points[p, 0] - c[0]) - h,
                        abs(points[p, 1] - c[1]) - h,
                        abs(points[p, 2] - c[2]) - h,
                    )
                    if dx <= 0.0 and dy <= 0.0 and dz <= 0.0:
                        if max(dx, dy, dz) < bound:
                            return True
                        continue
                    d2 = max(dx, 0.0) ** 2 + max(dy, 0.0) ** 2 + max(dz, 0.0) ** 2
                    if bound > 0.0 and d2 < bound * bound:
                        return True
                u += 1
    return False
