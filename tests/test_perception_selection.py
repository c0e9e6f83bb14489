"""Selection by the index-finger line: image boxes, the border, and the 3-D ray beside it."""

from __future__ import annotations

import numpy as np
import pytest

from baseplace.perception.selection import border_distance, depth_hole, image_ray, nearest_box


def _finger(tip, direction, step=10.0, dim=2):
    L = np.zeros((21, dim))
    d = np.asarray(direction, float) / np.linalg.norm(direction)
    for k, i in enumerate((8, 7, 6, 5)):
        L[i] = np.asarray(tip, float) - k * step * d
    return L


def test_the_line_selects_the_first_box_it_enters_and_stops_there():
    L = _finger([50, 100], [1, 0])
    boxes = [[[200, 90], [220, 110]], [[100, 95], [120, 105]], [[60, 0], [80, 20]]]
    ray = image_ray(L, boxes, 320, 240)
    assert ray.hit == 1 and ray.length == pytest.approx(100 - 50 - 0.5)
    assert ray.end == pytest.approx([99.5, 100])


def test_a_box_behind_the_fingertip_or_beside_the_line_is_not_selected():
    L = _finger([150, 100], [1, 0])
    ray = image_ray(L, [[[100, 90], [120, 110]], [[200, 120], [220, 140]]], 320, 240)
    assert ray.hit is None and ray.length == pytest.approx(319.5 - 150)  # to the border


def test_the_border_distance_in_every_direction():
    assert border_distance([10, 10], [-1, 0], 100, 50) == pytest.approx(10.5)
    assert border_distance([10, 10], [0, 1], 100, 50) == pytest.approx(39.5)
    d = np.array([1.0, 1.0]) / np.sqrt(2)
    assert border_distance([10, 10], d, 100, 50) == pytest.approx(39.5 * np.sqrt(2))


def test_the_longest_run_of_the_line_without_depth():
    depth = np.ones((10, 100))
    depth[:, 30:35] = np.nan
    depth[:, 60:80] = np.nan
    ray = image_ray(_finger([10, 5], [1, 0]), np.zeros((0, 2, 2)), 100, 10)
    n, at = depth_hole(ray, depth)
    assert n == 20 and at == pytest.approx([60, 5])
    assert depth_hole(ray, np.ones((10, 100))) == (0, None)


def test_the_nearest_rule_takes_the_box_centre_closest_in_angle_within_the_limit():
    L = _finger([50, 100], [1, 0])
    ray = image_ray(L, np.zeros((0, 2, 2)), 320, 240)
    grazed = [[100, 100.5], [104, 140]]  # its corner touches the line: the seed's rule takes it
    aimed = [[200, 92], [220, 112]]  # its centre lies 0.5 deg off the line
    assert image_ray(L, [grazed, aimed], 320, 240).hit == 0
    chosen = nearest_box(ray, [grazed, aimed])
    assert chosen.hit == 1 and chosen.length == pytest.approx(160, abs=0.1)
    assert nearest_box(ray, [[[100, 150], [110, 160]]]).hit is None  # 44 deg off: nothing
    assert nearest_box(ray, [[[100, 150], [110, 160]]], max_angle_deg=50).hit == 0
