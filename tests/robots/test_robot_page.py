"""The robot page of a robot with 100,000 topics shows one page of them, never all (speed: bench, not here)."""

import pytest
from django.urls import reverse

from robots.models import Robot, Topic

pytestmark = [pytest.mark.timeout(120), pytest.mark.django_db]

TOPICS = 100_000


@pytest.fixture
def crowded() -> Robot:
    """A robot with 100,000 topics, as a hostile or very large endpoint would register it."""
    robot = Robot.objects.create(name="crowded", endpoint="ws://127.0.0.1:9", link_status=Robot.Link.ONLINE)
    Topic.objects.bulk_create(
        (Topic(robot=robot, name=f"/t/{i:06d}", type="std_msgs/Bool") for i in range(TOPICS)), batch_size=5000
    )
    return robot


def test_the_page_of_a_100000_topic_robot_shows_one_page_of_topics_and_the_count(crowded, client_for, viewer):
    """One robot, two pages (100,000 rows take seconds to insert: one fixture for both looks)."""
    url = reverse("robot-detail", args=[crowded.pk])
    page = client_for(viewer).get(url)
    text = page.content.decode()
    assert page.status_code == 200
    assert f"Topics ({TOPICS})" in text
    assert text.count("<code>/t/") == 100 and "/t/000099" in text and "/t/000100" not in text
    assert "topics: page 1 of 1000" in text and 'href="?topics=2#topics"' in text
    assert len(page.content) < 100_000  # the issue saw 8.8 MB
    last = client_for(viewer).get(url, {"topics": 1000}).content.decode()
    assert "/t/099999" in last and "/t/099899" not in last and "topics: page 1000 of 1000" in last


def test_a_small_robot_has_no_pager(client_for, viewer):
    robot = Robot.objects.create(name="small", endpoint="ws://127.0.0.1:8")
    Topic.objects.create(robot=robot, name="/cmd_vel", type="geometry_msgs/Twist")
    text = client_for(viewer).get(reverse("robot-detail", args=[robot.pk])).content.decode()
    assert "Topics (1)" in text and 'class="pager"' not in text
