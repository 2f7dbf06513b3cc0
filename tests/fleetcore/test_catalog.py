"""One robot-model catalog: the portal's limits and the simulator's bodies come from it and agree."""

import pytest

from fleetcore import catalog
from robots import urdf


@pytest.mark.parametrize("key", sorted(catalog.MODELS))
def test_the_footprint_the_portal_reads_is_the_body_the_simulator_moves(key):
    profile = catalog.MODELS[key]
    footprint = urdf.parse(catalog.urdf("r", profile)).footprint
    xs, ys = [p[0] for p in footprint], [p[1] for p in footprint]
    half_l, half_w, off = profile.length / 2, profile.width / 2, profile.offset_x
    assert (min(xs), max(xs)) == pytest.approx((off - half_l, off + half_l), abs=1e-3)
    assert (min(ys), max(ys)) == pytest.approx((-half_w, half_w), abs=1e-3)


@pytest.mark.parametrize(("key", "ros"), [("turtlebot3_burger", 1), ("husky", 1), ("tiago", 1), ("spot", 1)])
def test_the_simulated_model_drives_within_the_limits_registration_gives_it(key, ros):
    profile = catalog.MODELS[key]
    assert (profile.max_v, profile.max_w) == catalog.limit(key, ros)
