"""Alerts left open by a shutdown are settled when the links come up again."""

import pytest

from robots.models import Robot


@pytest.mark.django_db(transaction=True)
def test_an_offline_alert_left_by_a_shutdown_is_settled_when_the_link_is_up():
    """make run stopped while a robot was offline; at the next start registration writes it online, so the
    link coming up changes no status: the alert left open is resolved all the same."""
    from alerts import raise_alert
    from alerts.models import Alert
    from robots.links import set_link_status

    robot = Robot.objects.create(name="leftover", endpoint="ws://127.0.0.1:9", link_status=Robot.Link.ONLINE)
    other = Robot.objects.create(
        name="elsewhere", endpoint="ws://127.0.0.1:10", link_status=Robot.Link.ONLINE
    )
    raise_alert("robot_offline", robot, "link to ws://127.0.0.1:9 lost")
    raise_alert("robot_offline", other, "link to ws://127.0.0.1:10 lost")
    assert set_link_status("ws://127.0.0.1:9", True) == []  # no status changed
    settled = Alert.objects.get(robot=robot)
    assert settled.resolved_at is not None and "left open from before" in settled.resolution
    assert Alert.objects.get(robot=other).resolved_at is None  # another endpoint's link is not up
