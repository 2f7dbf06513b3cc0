"""URDF facts: wheels, legs, footprint; a broken URDF is reported, not fatal."""

import pytest

from fleetcore.catalog import MODELS
from fleetcore.catalog import urdf as sim_urdf
from robots import urdf

TIAGO_LIKE = """<robot name="tiago">
  <link name="base_link"><collision><origin xyz="0 0 0.1"/><geometry><cylinder radius="0.275" length="0.2"/></geometry></collision></link>
  <joint name="wheel_left_joint" type="continuous"><parent link="base_link"/><child link="wheel_left_link"/></joint>
  <joint name="wheel_right_joint" type="continuous"><parent link="base_link"/><child link="wheel_right_link"/></joint>
  <joint name="caster_front_left_1_joint" type="continuous"><parent link="base_link"/><child link="caster_front_left_1_link"/></joint>
  <joint name="suspension_left_joint" type="prismatic"><parent link="base_link"/><child link="s"/></joint>
</robot>"""


def test_wheels_are_continuous_wheel_joints_not_casters():
    facts = urdf.parse(TIAGO_LIKE)
    assert facts.name == "tiago"
    assert facts.wheel_joints == ["wheel_left_joint", "wheel_right_joint"]
    assert facts.drive == "wheeled"
    assert facts.footprint == [[-0.275, -0.275], [-0.275, 0.275], [0.275, 0.275], [0.275, -0.275]]


@pytest.mark.parametrize(
    ("key", "wheels", "drive"),
    [("husky", 4, "wheeled"), ("turtlebot3_burger", 2, "wheeled"), ("spot", 0, "legged")],
)
def test_simulator_urdfs(key, wheels, drive):
    facts = urdf.parse(sim_urdf("r", MODELS[key]))
    assert (facts.wheel_count, facts.drive) == (wheels, drive)
    if drive == "legged":
        assert facts.leg_count == 4 and len(facts.leg_joints) == 12


def test_box_footprint_follows_the_collision_origin():
    text = '<robot name="b"><link name="base_link"><collision><origin xyz="-0.032 0 0.07"/><geometry><box size="0.14 0.14 0.143"/></geometry></collision></link></robot>'
    assert urdf.parse(text).footprint == [[-0.102, -0.07], [-0.102, 0.07], [0.038, 0.07], [0.038, -0.07]]


@pytest.mark.parametrize(
    ("text", "reason"),
    [
        ("", "empty"),
        ("<robot name='x'><link>", "not XML"),
        ("<sdf version='1.6'/>", "not <robot>"),
        (None, "empty"),
    ],
)
def test_broken_urdf_raises_a_clear_error(text, reason):
    with pytest.raises(urdf.URDFError, match=reason):
        urdf.parse(text)
