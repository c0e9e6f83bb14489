from __future__ import annotations

import pytest

from baseplace.errors import InputError
from baseplace.robots.model import Robot
from baseplace.robots.spec import load_spec
from conftest import DATA


def test_toml_and_yaml_robot_files(planar3):
    yaml_robot = Robot(DATA / "planar3.yaml")
    assert yaml_robot.arm().joint_names == planar3.arm().joint_names
    assert yaml_robot.spec.footprint_polygon is not None and planar3.spec.footprint_radius == 0.25
    assert yaml_robot.spec.footprint_bounding_radius == pytest.approx((0.3**2 + 0.2**2) ** 0.5)


def _write(tmp_path, text, name="r.toml"):
    (tmp_path / "planar3.urdf").write_text((DATA / "planar3.urdf").read_text())
    path = tmp_path / name
    path.write_text(text)
    return path


BASE = 'name = "x"\nurdf = "planar3.urdf"\nbase_frame = "base_link"\nfootprint = { radius = 0.2 }\n'


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (BASE + '[arms.arm]\njoints = ["joint1"]\ntcp_frame = "nope"\n', "unknown TCP frame .* valid: .*tool0"),
        (BASE + '[arms.arm]\njoints = ["jointX"]\ntcp_frame = "tool0"\n', "unknown joint .* valid: .*joint1"),
        (BASE.replace("base_link", "base_nope") + '[arms.arm]\njoints = ["joint1"]\ntcp_frame = "tool0"\n',
         "unknown base frame"),
        (BASE + '[arms.arm]\njoints = ["joint1"]\n', "needs 'joints' and 'tcp_frame'"),
        (BASE + "colour = 1\n", "unknown key"),
        ('name = "x"\n', "missing required key"),
        ("name = = \n", "cannot parse robot file"),
        (BASE + '[arms.arm]\njoints = ["joint1"]\ntcp_frame = "tool0"\n[joint_limits]\njoint1 = [1, -1]\n',
         "lo < hi"),
    ],
)  # fmt: skip
def test_bad_robot_files(tmp_path, text, message):
    path = _write(tmp_path, text)
    with pytest.raises(InputError, match=message):
        Robot(path).arm()


def test_joint_off_the_tcp_chain(tmp_path):
    path = _write(tmp_path, BASE + '[arms.arm]\njoints = ["joint2"]\ntcp_frame = "link1"\n')
    with pytest.raises(InputError, match="do not move TCP frame 'link1'"):
        Robot(path).arm()


def test_malformed_urdf_is_one_line(tmp_path):
    (tmp_path / "broken.urdf").write_text((DATA / "broken.urdf").read_text())
    path = tmp_path / "r.toml"
    path.write_text(
        BASE.replace("planar3.urdf", "broken.urdf") + '[arms.arm]\njoints = ["j"]\ntcp_frame = "a"\n'
    )
    with pytest.raises(InputError, match="cannot parse URDF") as info:
        Robot(path)
    assert "\n" not in str(info.value)


def test_unknown_builtin_lists_choices():
    with pytest.raises(InputError, match="valid: .*pr2, tiago, tiago_dual"):
        load_spec("tiagoo")
