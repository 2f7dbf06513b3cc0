"""bench.odometry_rate runs its windows against a real simulator process and counts what arrives."""

import pytest

from bench import odometry_rate


@pytest.mark.timeout(120)
def test_each_way_of_asking_gets_odometry_from_every_robot():
    data = odometry_rate.run({"robots": 3, "busy": 0, "seconds": 1.0})
    asked = [(w["asked"], w["throttle_rate"], w["queue_length"]) for w in data["windows"]]
    assert asked == [(label, throttle, queue) for label, throttle, queue in odometry_rate.CONFIGS]
    for window in data["windows"]:
        # a 20 Hz odometry followed at one message a throttle: every robot heard, none at the publisher's rate
        assert 0 < window["hz"]["min"] <= window["hz"]["max"] < 15, window
