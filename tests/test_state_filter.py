"""The pre-filtered state check (world/state_filter.py) gives coal's verdict on every state.

The oracle is :meth:`Environment.colliding_arm_exact` (coal on every pair); the states are those a
reaching motion checks on generated table scenes (the table grid's noisy clouds): joint lines along
straight approaches, random configurations (RRT's samples) and, mostly, states within a fraction of
a millimetre of contact, found by bisecting lines between free and colliding states.
"""

from __future__ import annotations

import itertools

import coal
import numpy as np
import pinocchio as pin
import pytest

from baseplace.geometry.poses import pose_from_xyz_rpy
from baseplace.placement.motion import stowed_configuration
from baseplace.placement.pipeline import PlaceSettings, scene_checks, with_floor
from baseplace.placement.scene_cache import SceneCache
from baseplace.robots.ik import DampedLeastSquaresIK
from baseplace.world.environment import Environment
from baseplace.world.state_filter import StateFilter
from baseplace.world.state_kernel import _arm_centres
from baseplace_experiments.execution_experiment import trial_scene
from baseplace_experiments.table_grid import TableGridSettings

# (seed, cell, grasp index (0: side along +x, 20: top-down), base offset from the grasp (x, y) [m], base yaw)
SCENES = [(0, (0, 0), 0, (-0.62, 0.15), 0.0), (1, (1, 1), 20, (0.1, -0.6), 1.87)]


def _environments(tiago, seed, cell, grasp):
    s = TableGridSettings()
    _, p_est, seen = trial_scene(seed, cell, s)
    points = with_floor(seen, 0.0)
    cache = SceneCache(points)
    grasps = s.grasps(p_est, s.method_top_below)
    grasps[: s.grasp_directions, 2, 3] += 0.04
    target = grasps[grasp]
    arm = tiago.arm()
    checks = scene_checks(
        tiago, arm.name, points, cache.terrain(None), target[None], PlaceSettings(), "auto", cache
    )
    motion = checks.verifier.motion
    assert motion is not None and motion.approach_environment is not None
    return target, motion.environment, motion.approach_environment


def _states(tiago, target, offset, yaw, rng):
    """(base pose, arm states): an approach line, the line from the stowed configuration, random samples."""
    arm = tiago.arm()
    xy = target[:2, 3] + offset
    T_base = pose_from_xyz_rpy([xy[0], xy[1], 0.0, 0.0, 0.0, yaw])
    T_base_tcp = np.linalg.inv(T_base) @ target
    ik = DampedLeastSquaresIK(arm, restarts=20)
    q_grasp = ik.solve(T_base_tcp, rng)
    assert q_grasp is not None
    states = [q_grasp]
    q = q_grasp
    for k in range(1, 16):  # 0.15 m back along the approach axis, joint lines 8 states a step
        T = T_base_tcp.copy()
        T[:3, 3] -= 0.01 * k * T_base_tcp[:3, 0]
        q_next = ik.solve_from(T, q[None])
        if q_next is None:
            break
        states += [q + (q_next - q) * t for t in np.linspace(0.125, 1.0, 8)]
        q = q_next
    q0 = stowed_configuration(tiago, arm)
    states += [q0 + (q_grasp - q0) * t for t in np.linspace(0.0, 1.0, 60)]
    states += list(arm.sample(rng, 300))
    return T_base, np.array(states)


def _near_contact(env, arm, T_base, states, rng, pairs=120, depth=10):
    """States on both sides of contact: bisect lines from free to colliding states ``depth`` times."""
    verdict = np.array([env.colliding_arm_exact(arm, q, T_base) for q in states])
    free, hit = states[~verdict], states[verdict]
    assert len(free) and len(hit)
    out = []
    for _ in range(pairs):
        a, b = free[rng.integers(len(free))], hit[rng.integers(len(hit))]
        for _ in range(depth):
            m = (a + b) / 2
            if env.colliding_arm_exact(arm, m, T_base):
                b = m
            else:
                a = m
        out += [a, b]
    return np.array(out)


def scene_models(tiago, rng):
    """Per table scene of :data:`SCENES` and collision model (transit, approach): (environment, base pose, states).

    The states (:func:`_states`) are drawn once per scene from ``rng``, lazily: a caller that draws
    from ``rng`` for one model does so before the next scene's states are drawn.
    """
    for scene_seed, cell, grasp, offset, yaw in SCENES:
        target, transit, approach = _environments(tiago, scene_seed, cell, grasp)
        T_base, states = _states(tiago, target, offset, yaw, rng)
        for env in (transit, approach):
            yield env, T_base, states


def table_scene_states(tiago, seed: int, every: int = 1, pairs: int = 120):
    """Per table scene and collision model (transit, approach): (environment, base pose, states (N, n)).

    Every ``every``-th drawn state and ``pairs`` bisected pairs around contact (:func:`_near_contact`).
    """
    rng = np.random.default_rng(seed)
    arm = tiago.arm()
    out = []
    for env, T_base, states in scene_models(tiago, rng):
        near = _near_contact(env, arm, T_base, states, rng, pairs)
        out.append((env, T_base, np.vstack([states[::every], near])))
    return out


@pytest.fixture(scope="module")
def table_states(tiago):
    """Per scene and collision model (transit, approach): (environment, base pose, states (N, n))."""
    return table_scene_states(tiago, 7)


def test_verdicts_are_coals_on_table_scenes(tiago, table_states):
    arm = tiago.arm()
    total, colliding, coal_pairs, proven = 0, 0, 0, 0
    for env, T_base, states in table_states:
        fast = np.array([env.colliding_arm(arm, q, T_base) for q in states])
        exact = np.array([env.colliding_arm_exact(arm, q, T_base) for q in states])
        wrong = np.flatnonzero(fast != exact)
        assert len(wrong) == 0, (
            f"{len(wrong)} of {len(states)} verdicts differ from coal's, first at {states[wrong[0]]}"
        )
        total += len(states)
        colliding += int(exact.sum())
        coal_pairs += env.state_filter(arm).coal_pairs
        proven += env.state_filter(arm).proven_states
    assert total >= 2000
    assert 0.2 * total < colliding < 0.8 * total  # both verdicts, many states at contact
    assert coal_pairs > 0  # the near states reach coal
    assert proven > 0.1 * colliding  # and witness balls decide many contacts without it
    print(f"{total} states, {colliding} touching, {proven} proven by witness balls")


def test_contacts_unchanged(tiago, table_states):
    """contacts_arm names what coal finds touching, whichever base pose the filter placed the scene for last."""
    arm = tiago.arm()
    env, T_base, states = table_states[1]
    other_T = table_states[3][1]
    for q in states[-60:]:
        env.colliding_arm(arm, q, other_T)  # scene placed for another base pose
        contacts = env.contacts_arm(arm, q, T_base)
        assert bool(contacts) == env.colliding_arm_exact(arm, q, T_base)
        assert contacts == _contacts_oracle(env, arm, q, T_base)


def _contacts_oracle(env, arm, q, T_base):
    """What main's contacts_arm returned: every pair by pinocchio on fresh data, the scene placed for ``T_base``."""
    geom = env.geom.copy()
    T_root_world = env._T_root_base * pin.SE3(np.asarray(T_base)).inverse()
    for gid in env.env_ids:
        geom.geometryObjects[gid].placement = T_root_world * env._T_world_env.get(gid, pin.SE3.Identity())
    gdata = pin.GeometryData(geom)
    for request, own in zip(gdata.collisionRequests, env.geom_data.collisionRequests, strict=True):
        request.security_margin = own.security_margin
    q_full = arm.to_pinocchio(q, env.robot.q_reference)
    pin.computeCollisions(env.model, env.model.createData(), geom, gdata, q_full, False)
    out = {(a, f"self: {b}") for a, b in env._self.colliding_pairs(q_full, arm)}
    for pair, result in zip(geom.collisionPairs, gdata.collisionResults, strict=True):
        if result.isCollision():
            out.add((env._link(pair.first), geom.geometryObjects[pair.second].name))
    return sorted(out)


def _surface_points(geometry):
    """(k, 3) points of the geometry in its frame: a mesh's vertices, a primitive's extreme points."""
    if isinstance(geometry, coal.Box):
        h = np.asarray(geometry.halfSide)
        return np.array(list(itertools.product(*[(-v, v) for v in h])))
    if isinstance(geometry, coal.Cylinder):
        t = np.linspace(0.0, 2 * np.pi, 64, endpoint=False)
        ring = np.c_[geometry.radius * np.cos(t), geometry.radius * np.sin(t)]
        return np.vstack([np.c_[ring, np.full(64, z)] for z in (-geometry.halfLength, geometry.halfLength)])
    if isinstance(geometry, coal.Sphere):
        d = np.random.default_rng(0).normal(size=(200, 3))
        return geometry.radius * d / np.linalg.norm(d, axis=1, keepdims=True)
    return np.asarray(geometry.vertices(), dtype=float).reshape(-1, 3)


def _placed_states(tiago, seed, n):
    """TIAGo's filter (no scene) and n random arm states, each with the geometries placed by pinocchio FK.

    Yields (filter, geometry model, arm state, the arm's base in the world (4, 4), per geometry
    its world pose (pin.SE3)) at one base pose.
    """
    arm = tiago.arm()
    env = Environment(tiago, {}, self_collision=False)
    filt = env.state_filter(arm)
    geom, model = env.geom, tiago.model
    data, gdata = model.createData(), pin.GeometryData(geom)
    T_base = pose_from_xyz_rpy([0.4, -0.3, 0.0, 0.0, 0.0, 0.7])
    T_world_root = pin.SE3(T_base) * env._T_root_base.inverse()
    for q in arm.sample(np.random.default_rng(seed), n):
        pin.updateGeometryPlacements(model, data, geom, gdata, arm.to_pinocchio(q, tiago.q_reference))
        placed = [T_world_root * gdata.oMg[k] for k in range(len(geom.geometryObjects))]
        yield filt, geom, q, T_base @ filt._T_base_armbase, placed


def test_bounding_spheres_hold_their_geometry(tiago):
    """Every TIAGo collision geometry, placed by pinocchio FK, lies in the sphere the filter places."""
    worst, points = -np.inf, None
    for filt, geom, q, T, placed in _placed_states(tiago, 3, 50):
        points = points or [_surface_points(obj.geometry) for obj in geom.geometryObjects]
        C = filt.centres(q)
        C_world = C @ T[:3, :3].T + T[:3, 3]
        for k, P in enumerate(points):
            M = placed[k]
            p_world = P @ M.rotation.T + M.translation
            gap = np.linalg.norm(p_world - C_world[k], axis=1).max() - filt.radius[k]
            worst = max(worst, gap)
    assert worst <= 1e-9, f"a geometry point lies {worst} m outside its bounding sphere"
    assert points is not None and len(points) == len(filt.radius) == 64


def test_contact_balls_lie_within_their_geometry(tiago):
    """Every witness ball, placed by the filter's joint frames, lies within its geometry as coal, placed by pinocchio FK, finds it.

    The oracle: coal's signed distance from a tiny sphere at the ball's centre to the geometry
    (inside a solid: minus the depth) is at most minus the ball's radius (a mesh's: 0, a point of
    its surface).
    """
    arm = tiago.arm()
    tiny, request = coal.Sphere(1e-6), coal.DistanceRequest()
    worst, solid = -np.inf, 0
    for filt, geom, q, T, placed in _placed_states(tiago, 5, 10):
        start, local, radius = filt._contact_balls
        owner = np.repeat(np.arange(len(start) - 1), np.diff(start))
        C = np.empty_like(local)
        _arm_centres(q, arm.placements, arm.axes, arm.kinds, filt.joint[owner], local, C)
        C_world = C @ T[:3, :3].T + T[:3, 3]
        for b, k in enumerate(owner.tolist()):
            M = placed[k]
            result = coal.DistanceResult()
            d = coal.distance(
                geom.geometryObjects[k].geometry, coal.Transform3s(M.rotation, M.translation), tiny,
                coal.Transform3s(np.eye(3), C_world[b]), request, result,
            )  # fmt: skip
            worst = max(worst, d + 1e-6 + radius[b])
            solid += radius[b] > 0
    assert worst <= 1e-6, f"a witness ball reaches {worst} m outside its geometry"
    assert len(start) == 65 and solid > 0 and len(radius) > 64


def test_moving_geometries_are_the_arms(tiago):
    """The hand and arm links move with the arm joints; the base and torso do not."""
    arm = tiago.arm()
    filt = Environment(tiago, {}, self_collision=False).state_filter(arm)
    assert isinstance(filt, StateFilter)
    assert (filt.joint >= 0).sum() > 20 and (filt.joint < 0).sum() > 5
