"""The scene near the grasped object at sensor resolution, kept at a clearance (issue 25, Must show 1).

Oracle: coal on the true shapes (a box for the table, cylinders for the bottles) against the
robot's collision meshes loaded here from the URDF, never the code's own collision model.
"""

from __future__ import annotations

import json

import coal
import numpy as np
import pinocchio as pin
import pytest

from baseplace.errors import InputError
from baseplace.geometry.poses import pose_from_xyz_rpy
from baseplace.placement.pipeline import PlaceSettings, object_checks, place, with_floor
from baseplace.reachability.storage import save_map
from baseplace.robots.ik import DampedLeastSquaresIK
from baseplace.terrain.voxels import VoxelMap
from baseplace.world.environment import GRASPED, Environment, contact_groups
from baseplace.world.grasped_object import GraspedObject, find_grasped_object
from baseplace.world.sensor_resolution import (
    SMOOTH_VOTES,
    SPACING_NEIGHBOURS,
    RawCells,
    SupportPlane,
    SurfaceCells,
    group_parts,
    sample_spacing,
)
from baseplace.world.support_plane import SUPPORT_PLANE
from conftest import run_cli

GRASP = pose_from_xyz_rpy([0.75, -0.15, 0.85, 0.0, 0.0, 0.0])  # side grasp, base at the origin
TABLE_XY = ((0.45, 1.25), (-0.6, 0.45))
RADIUS, HEIGHT = 0.03, 0.2  # the bottles
GAP = 0.016  # the hand's lowest point over the true table top (the scene)
SIGMA = 0.003  # sensor noise per axis [m]

Shape = tuple[coal.CollisionGeometry, coal.Transform3s]


def _at(xyz) -> coal.Transform3s:
    return coal.Transform3s(np.eye(3), np.asarray(xyz, dtype=float))


def _table(top: float) -> Shape:
    (x0, x1), (y0, y1) = TABLE_XY
    return coal.Box(x1 - x0, y1 - y0, 0.04), _at([(x0 + x1) / 2, (y0 + y1) / 2, top - 0.02])


def _bottle(xy, top: float) -> Shape:
    return coal.Cylinder(RADIUS, HEIGHT), _at([xy[0], xy[1], top + HEIGHT / 2])


class Oracle:
    """The robot's collision meshes, loaded from the URDF here, against true coal shapes."""

    def __init__(self, robot) -> None:
        self.robot, self.model = robot, robot.model
        self.geom = pin.buildGeomFromUrdf(self.model, str(robot.spec.urdf), pin.COLLISION,
                                          package_dirs=[str(p) for p in robot.spec.package_dirs])  # fmt: skip

    def _placed(self, q_full, T_world_base):
        data, gdata = self.model.createData(), pin.GeometryData(self.geom)
        pin.framesForwardKinematics(self.model, data, q_full)
        pin.updateGeometryPlacements(self.model, data, self.geom, gdata, q_full)
        T_world_root = (
            np.asarray(T_world_base)
            @ data.oMf[self.model.getFrameId(self.robot.spec.base_frame)].inverse().homogeneous
        )
        for k, g in enumerate(self.geom.geometryObjects):
            T = T_world_root @ gdata.oMg[k].homogeneous
            yield (
                str(self.model.frames[g.parentFrame].name),
                g.geometry,
                coal.Transform3s(T[:3, :3], T[:3, 3]),
            )

    def distances(self, q_full, T_world_base, shape: Shape) -> dict[str, float]:
        """Per link, its smallest coal distance to the shape [m] (negative: penetration)."""
        out: dict[str, float] = {}
        for link, g, T in self._placed(q_full, T_world_base):
            d = coal.distance(g, T, shape[0], shape[1], coal.DistanceRequest(), coal.DistanceResult())
            out[link] = min(out.get(link, np.inf), float(d))
        return out

    def touching(self, q_full, T_world_base, shapes: dict[str, Shape]) -> set[tuple[str, str]]:
        out = set()
        for link, g, T in self._placed(q_full, T_world_base):
            for name, (shape, S) in shapes.items():
                if coal.collide(g, T, shape, S, coal.CollisionRequest(), coal.CollisionResult()):
                    out.add((link, name))
        return out


@pytest.fixture(scope="module")
def grasp_scene(tiago):
    """The IK configuration at GRASP (base at the origin), the grasp point, the table top for GAP
    under the hand, and the neighbour's y for a 3 cm gap to the hand, all found with the oracle."""
    oracle = Oracle(tiago)
    hand = _hand_links(tiago)
    arm = tiago.arm()
    q = DampedLeastSquaresIK(arm).solve(GRASP, np.random.default_rng(0))
    assert q is not None
    q_full = arm.to_pinocchio(q, tiago.q_reference)
    point = (GRASP @ tiago.T_tcp_grasp())[:3, 3]

    def lowest(top: float) -> float:
        return min(d for link, d in oracle.distances(q_full, np.eye(4), _table(top)).items() if link in hand)

    top = 0.5
    for _ in range(30):  # secant steps: raise the table until the hand is GAP above it
        top += lowest(top) - GAP
    assert lowest(top) == pytest.approx(GAP, abs=2e-4)

    def beside(y: float) -> float:
        return min(d for link, d in oracle.distances(q_full, np.eye(4), _bottle((point[0], y), top)).items()
                   if link in hand)  # fmt: skip

    y = point[1] - 0.2  # the neighbour on the hand's right, moved until it is 3 cm from the hand
    for _ in range(30):
        y += beside(y) - 0.03
    assert beside(y) == pytest.approx(0.03, abs=2e-4)
    return oracle, q_full, point, top, y


def _cloud(point, top: float, neighbour_y: float, rng: np.random.Generator) -> np.ndarray:
    """The table top (1 cm grid), the grasped bottle and its neighbour, 3 mm Gaussian noise; a floor."""
    (x0, x1), (y0, y1) = TABLE_XY
    X, Y = np.meshgrid(np.arange(x0, x1, 0.01), np.arange(y0, y1, 0.01))
    table = np.c_[X.ravel(), Y.ravel(), np.full(X.size, top)]
    a, z = np.meshgrid(
        np.linspace(0, 2 * np.pi, 40, endpoint=False), np.arange(top + 0.005, top + HEIGHT, 0.01)
    )
    ring = np.c_[RADIUS * np.cos(a).ravel(), RADIUS * np.sin(a).ravel(), z.ravel()]
    bottles = [ring + np.array([point[0], y, 0.0]) for y in (point[1], neighbour_y)]
    scene = np.concatenate([table, *bottles])
    return with_floor(scene + rng.normal(0.0, SIGMA, scene.shape), 0.0)


def _place(tiago, tiago_map, point, top, neighbour_y, grasped="auto", **settings):
    cloud = _cloud(point, top, neighbour_y, np.random.default_rng(7))
    return place(tiago, tiago_map, cloud, GRASP, PlaceSettings(tries=60, **settings), np.random.default_rng(0),
                 grasped=grasped)  # fmt: skip


def _contact_groups(point, top: float, neighbour_y: float):
    """(groups, grasped object's group) of :func:`~baseplace.world.environment.contact_groups` on the scene's cloud."""
    cloud = _cloud(point, top, neighbour_y, np.random.default_rng(7))
    obj = find_grasped_object(cloud, point)
    assert obj is not None
    voxels = VoxelMap.from_points(cloud)
    groups, object_group = contact_groups(voxels, voxels, obj, cloud)
    return groups, object_group


def _hand_links(robot) -> set[str]:
    model = robot.model
    last = model.getJointId(robot.arm().joint_names[-1])
    return {f.name for f in model.frames if last in model.supports[f.parentJoint]}


def test_a_side_grasp_16mm_over_a_noisy_table_3cm_from_a_neighbour_is_found_and_touches_nothing(
    tiago, tiago_map, grasp_scene
):
    oracle, _, point, top, y = grasp_scene
    res = _place(tiago, tiago_map, point, top, y)
    assert res.grasped is not None and res.grasped.size[1] < 0.08  # the bottle, not its neighbour too
    assert res.placements, (dict(res.failures), dict(res.contacts))
    assert 0.003 <= res.clearance <= 0.012 and res.clearance_note.startswith("3 sigma")
    shapes = {"table": _table(top), "bottle": _bottle(point, top), "neighbour": _bottle((point[0], y), top)}
    hand = _hand_links(tiago)
    arm = tiago.arm()
    for p in res.placements:
        assert p.motions is not None
        states = [*p.joints, *p.motions[0].path, *p.motions[0].approach]
        for q in states:
            for link, what in oracle.touching(arm.to_pinocchio(q, tiago.q_reference), p.T_world_base, shapes):
                assert what == "bottle" and link in hand, (link, what)


def _pushed(distances: dict[str, float]) -> set[str]:
    return {link for link, d in distances.items() if d < 0}


def test_fingers_5mm_into_the_table_are_refused_naming_the_link(tiago, tiago_map, grasp_scene):
    oracle, q_full, point, top, y = grasp_scene
    raised = top + GAP + 0.005  # the same grasp, 5 mm lower relative to the table and the bottles
    d = {
        link: v
        for link, v in oracle.distances(q_full, np.eye(4), _table(raised)).items()
        if link in _hand_links(tiago)
    }
    into = _pushed(d)  # 5 mm by construction; coal's penetration depth of a mesh is not exact
    assert into
    res = _place(tiago, tiago_map, point, raised, y)
    assert not res.placements
    assert any(link in into and what in ("support_plane", "support") for link, what in res.contacts), dict(
        res.contacts
    )


def test_a_link_5mm_into_the_neighbour_is_refused_naming_the_link(tiago, tiago_map, grasp_scene):
    oracle, q_full, point, top, y = grasp_scene
    closer = y + 0.035  # was 3 cm from the robot: now 5 mm into it
    d = oracle.distances(q_full, np.eye(4), _bottle((point[0], closer), top))
    d = {link: v for link, v in d.items() if link in _hand_links(tiago)}
    into = _pushed(d)  # 5 mm by construction (a cylinder moved along y against the hand)
    assert into
    # given: "auto" takes bottles 2.25 cm apart for one object, which the hand may touch
    bottle = GraspedObject.cylinder([point[0], point[1], top + HEIGHT / 2], RADIUS, HEIGHT)
    res = _place(tiago, tiago_map, point, top, closer, grasped=bottle)
    assert not res.placements
    assert any(link in into and what == "obstacle" for link, what in res.contacts), dict(res.contacts)


@pytest.mark.parametrize("bad", [-0.001, float("nan"), float("inf"), 0.2])
def test_a_bad_clearance_is_an_input_error(bad):
    with pytest.raises(InputError, match="clearance"):
        PlaceSettings(clearance=bad)


@pytest.mark.parametrize("bad", ["-0.001", "nan", "inf", "0.2"])
def test_cli_bad_clearance_exits_2_with_one_line(tmp_path, bad):
    cloud = tmp_path / "cloud.npy"
    np.save(cloud, np.zeros((10, 3)))
    out = run_cli("place", "--cloud", str(cloud), "--target", "0.75 -0.15 0.85 0 0 0", f"--clearance={bad}")
    assert out.returncode == 2
    line = out.stderr.strip()
    assert "\n" not in line and "clearance" in line


def test_cli_reports_the_clearance_and_how_it_was_derived(tiago_map, grasp_scene, tmp_path):
    _, _, point, top, y = grasp_scene
    cloud, map_file = tmp_path / "scene.npy", tmp_path / "tiago.rmap"
    np.save(cloud, _cloud(point, top, y, np.random.default_rng(7)))
    save_map(tiago_map, map_file)
    common = ["place", "--cloud", str(cloud), "--map", str(map_file), "--target", "0.75 -0.15 0.85 0 0 0",
              "--tries", "60", "--json"]  # fmt: skip
    derived = json.loads(run_cli(*common).stdout)
    assert derived["exit_code"] == 0 and derived["placements"]
    assert derived["clearance"]["derived"].startswith("3 sigma of the support plane's residuals (sigma 3.")
    assert 0.0085 <= derived["clearance"]["metres"] <= 0.0095  # 3 x 3 mm
    # the bound it keeps from the true surface: c - n, n the derived noise margin (0 at the default)
    n = derived["clearance"]["noise_margin"]
    assert n == derived["clearance"]["metres"] and derived["clearance"]["from_true_surface"] == 0.0
    given = json.loads(run_cli(*common, "--clearance", "0.03").stdout)
    # 3 cm: more than the hand's 16 mm over the table, so the grasp is refused, and says why
    assert given["clearance"] == {"metres": 0.03, "derived": "given", "noise_margin": n,
                                  "from_true_surface": round(0.03 - n, 5), "object_above_top": 0.0125}  # fmt: skip
    assert given["exit_code"] == 3


@pytest.mark.parametrize("bad", [-0.001, float("nan"), float("inf"), 0.2])
def test_service_request_bounds_the_clearance(bad):
    pydantic = pytest.importorskip("pydantic")
    from baseplace.serve.app import PlaceRequest

    ok = PlaceRequest(scene_id="s", targets=["0.75 -0.15 0.85 0 0 0"], clearance=0.005)
    assert ok.clearance == 0.005
    with pytest.raises(pydantic.ValidationError, match="clearance"):
        PlaceRequest(scene_id="s", targets=["0.75 -0.15 0.85 0 0 0"], clearance=bad)


def test_the_clearance_decides_whether_the_hand_16mm_over_the_plane_touches_it(tiago, grasp_scene):
    """The security margin reaches the exact plane: the hand 16 mm over the true top (the oracle)
    touches ``support_plane`` at a 20 mm clearance and not at 10 mm."""
    _, q_full, point, top, y = grasp_scene
    groups, object_group = _contact_groups(point, top, y)
    assert isinstance(groups[SUPPORT_PLANE], SupportPlane)
    arm, hand = tiago.arm(), _hand_links(tiago)

    def hand_on_plane(clearance: float) -> set[str]:
        env = Environment(tiago, groups, grasped=object_group, clearance=clearance)
        contacts = env.contacts_arm(arm, arm.from_pinocchio(q_full), np.eye(4))
        return {link for link, what in contacts if link in hand and what == SUPPORT_PLANE}

    assert hand_on_plane(0.010) == set()
    assert "hand_little_flex_3_link" in hand_on_plane(0.020)


def test_candidates_checks_keep_the_same_clearance(tiago, grasp_scene):
    """``candidates`` (object_checks) derives the clearance as ``place`` does, or takes the given one."""
    _, _, point, top, y = grasp_scene
    cloud = _cloud(point, top, y, np.random.default_rng(7))
    obj = find_grasped_object(cloud, point)
    derived = object_checks(tiago, "arm", None, cloud, obj, None)
    assert 0.0085 <= derived.environment.clearance <= 0.0095 and derived.clearance_note.startswith("3 sigma")
    given = object_checks(tiago, "arm", None, cloud, obj, None, clearance=0.02)
    assert given.environment.clearance == 0.02 and given.clearance_note == "given"
    with pytest.raises(InputError, match="clearance"):
        object_checks(tiago, "arm", None, cloud, obj, None, clearance=-0.01)


def test_each_scene_geometry_keeps_the_part_it_was_built_from(tiago, grasp_scene):
    """``Environment.parts``: per scene geometry its group's part, so a report can say what a link touched
    (smoothed or raw point cells, the exact plane); checked against the groups and coal's own cells."""
    _, _, point, top, y = grasp_scene
    groups, object_group = _contact_groups(point, top, y)
    env = Environment(tiago, groups, grasped=object_group, clearance=0.01)
    built = [(name, part) for name, g in [*groups.items(), (GRASPED, object_group)] for part in group_parts(g)
             if len(part)]  # fmt: skip
    assert len(env.parts) == len(built)
    for (gid, part), (name, given) in zip(env.parts.items(), built, strict=True):
        assert part is given and env.geom.geometryObjects[gid].name == name
        geometry = env.geom.geometryObjects[gid].geometry
        if isinstance(part, SupportPlane):
            assert isinstance(geometry, coal.ConvexBase) and geometry.num_points == 2 * len(part.hull)
        else:
            boxes = np.asarray(geometry.toBoxes())
            assert len(boxes) == len(part)
            np.testing.assert_allclose(boxes[:, 3], part.resolution)
    kinds = {type(p) for p in env.parts.values()}
    assert {SurfaceCells, RawCells, SupportPlane} <= kinds


def test_sample_spacing_against_every_distance():
    """The spacing near each query point against a brute-force reading of its definition.

    Each point's distance to its k-th nearest other point, scaled by sqrt(pi / k), and the median
    of it over the points nearest each query point (all distances computed).
    """
    rng = np.random.default_rng(11)
    p = np.c_[rng.uniform(0, 0.5, (1500, 2)), rng.normal(0, 0.003, 1500)]  # a noisy patch of plane
    q = rng.uniform(-0.1, 0.6, (40, 3))
    d = np.linalg.norm(p[:, None] - p[None], axis=2)
    own = np.sort(d, axis=1)[:, SPACING_NEIGHBOURS] * np.sqrt(np.pi / SPACING_NEIGHBOURS)
    votes = np.argsort(np.linalg.norm(q[:, None] - p[None], axis=2), axis=1)[:, :SMOOTH_VOTES]
    np.testing.assert_allclose(sample_spacing(p, q), np.median(own[votes], axis=1), rtol=1e-12)
    assert 0.010 < float(np.median(sample_spacing(p, q))) < 0.016  # 1500 samples on 0.25 m^2: 12.9 mm apart


def test_the_quadric_residual_is_a_least_squares_fit_per_neighbourhood():
    """``_smooth_residual`` (batched normal equations) against numpy's lstsq, one neighbourhood at a
    time: on a noisy paraboloid, a noisy edge and pure noise, the residuals' standard deviation of
    the quadric h = a + b u + c v + d u^2 + e u v + f v^2 agrees to 1e-9 relative."""
    from baseplace.world.sensor_resolution import _smooth_residual

    rng = np.random.default_rng(7)
    n, k = 60, 32
    uv = rng.uniform(-0.02, 0.02, (n, k, 2))
    curved = 3.0 * uv[..., 0] ** 2 + rng.normal(0.0, 5e-4, (n, k))
    edge = np.abs(uv[..., 0]) + rng.normal(0.0, 5e-4, (n, k))
    noise = rng.normal(0.0, 1e-3, (n, k))
    for h in (curved, edge, noise):
        local = np.concatenate([h[..., None], uv], axis=-1)  # (height, u, v) in a random frame
        axes = np.stack([np.linalg.qr(rng.normal(size=(3, 3)))[0] for _ in range(n)])
        centred = np.einsum("nkj,nij->nki", local, axes)  # local = centred @ axes
        got = _smooth_residual(centred, axes)
        for i in range(n):
            u, v = uv[i, :, 0], uv[i, :, 1]
            design = np.stack([np.ones(k), u, v, u * u, u * v, v * v], axis=1)
            coef = np.linalg.lstsq(design, h[i], rcond=None)[0]
            want = np.sqrt(np.sum((h[i] - design @ coef) ** 2) / (k - 6))
            assert got[i] == pytest.approx(want, rel=1e-9)
