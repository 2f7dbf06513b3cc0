"""Each page renders for each role; viewers see no controls; the registration page's choice works."""

import pytest
from django.urls import reverse

from access import leases
from audit.models import AuditEntry
from execution.models import Instruction
from robots.models import Binding
from tests.portal.conftest import slot_hours

PAGES = ["dashboard", "robot-list", "registration", "schedules", "history"]


def _pages(fleet):
    return [reverse(name) for name in PAGES] + [reverse("robot-detail", args=[fleet["turtlebot"].pk])]


@pytest.mark.parametrize("who", ["viewer", "operator", "fleet_admin"])
def test_every_page_renders_for_every_role(request, client_for, fleet, who):
    client = client_for(request.getfixturevalue(who))
    for path in _pages(fleet):
        response = client.get(path)
        assert response.status_code == 200, path
        assert b"turtlebot" in response.content, path


def test_viewer_sees_no_controls(client_for, viewer, fleet):
    client = client_for(viewer)
    dashboard = client.get("/").content.decode()
    assert "STOP ALL" not in dashboard
    assert 'id="instruction"' not in dashboard
    robot = client.get(reverse("robot-detail", args=[fleet["turtlebot"].pk])).content.decode()
    assert "Take control" not in robot
    assert 'aria-label="Teleoperation"' not in robot
    registration = client.get(reverse("registration")).content.decode()
    assert 'id="register-form"' not in registration
    assert ">Choose</button>" not in registration


def test_operator_sees_the_console_the_stop_button_and_teleop(client_for, operator, fleet):
    client = client_for(operator)
    dashboard = client.get("/").content.decode()
    assert '<label for="instruction">Instruction</label>' in dashboard
    assert "STOP ALL" in dashboard
    robot = client.get(reverse("robot-detail", args=[fleet["turtlebot"].pk])).content.decode()
    assert "Take control" in robot
    assert 'max="0.22"' in robot  # the speed slider stops at the robot's limit


def test_robot_page_shows_bindings_topics_facts_and_the_holder(client_for, viewer, operator, fleet):
    leases.take(operator, fleet["turtlebot"])
    page = client_for(viewer).get(reverse("robot-detail", args=[fleet["turtlebot"].pk])).content.decode()
    assert "/cmd_vel" in page and "exact" in page
    assert "needs a person" in page
    assert "/odom_raw" in page
    assert "<dt>Wheels</dt><dd>2</dd>" in page  # a fact of its description, labelled in words
    assert "held by otto" in page


def test_missing_robot_is_404(client_for, viewer, db):
    assert client_for(viewer).get(reverse("robot-detail", args=[999])).status_code == 404


def test_admin_resolves_a_needs_user_binding_from_the_registration_page(client_for, fleet_admin, fleet):
    client = client_for(fleet_admin)
    binding = Binding.objects.get(robot=fleet["turtlebot"], action="odometry")
    page = client.get(reverse("registration")).content.decode()
    assert "which topic carries <strong>odometry</strong>" in page
    response = client.post(reverse("choose-binding", args=[binding.pk]), {"target": "/odom_raw"}, follow=True)
    assert response.status_code == 200
    binding.refresh_from_db()
    assert (binding.target, binding.how, binding.needs_user) == ("/odom_raw", "user", False)
    assert "odometry now uses /odom_raw" in response.content.decode()
    assert AuditEntry.objects.filter(action="binding.choose", user=fleet_admin).exists()
    assert "which topic carries <strong>odometry</strong>" not in response.content.decode()


def test_a_choice_outside_the_candidates_is_refused_with_a_reason(client_for, fleet_admin, fleet):
    binding = Binding.objects.get(robot=fleet["turtlebot"], action="odometry")
    response = client_for(fleet_admin).post(
        reverse("choose-binding", args=[binding.pk]), {"target": "/cmd_vel"}, follow=True
    )
    binding.refresh_from_db()
    assert binding.needs_user and binding.target == ""
    assert "is not one of the candidates" in response.content.decode()


def test_operator_cannot_choose_a_binding(client_for, operator, fleet):
    binding = Binding.objects.get(robot=fleet["turtlebot"], action="odometry")
    response = client_for(operator).post(reverse("choose-binding", args=[binding.pk]), {"target": "/odom"})
    assert response.status_code == 403


def test_schedule_has_the_shape_of_table_12(client_for, viewer, fleet_admin, fleet):
    page = client_for(viewer).get(reverse("schedules")).content.decode()
    start, end = slot_hours()
    assert f"{start}–{end}" in page
    assert "A(0.2, 0.2) + rotate(5)" in page
    assert "FreeTime" in page  # the husky has no slot
    assert "slot-form" not in page
    assert "slot-form" in client_for(fleet_admin).get(reverse("schedules")).content.decode()


def test_history_filters_and_timings(client_for, viewer, operator, fleet):
    from datetime import timedelta

    first = Instruction.objects.create(
        text="move turtlebot to A", user=operator, status="succeeded", type="I"
    )
    first.interpreted_at = first.received_at + timedelta(milliseconds=12)
    first.finished_at = first.received_at + timedelta(seconds=3)
    first.save()
    first.robots.add(fleet["turtlebot"])
    Instruction.objects.create(text="fly to the roof", user=operator, status="needs_user", type="III")
    client = client_for(viewer)
    page = client.get(reverse("history")).content.decode()
    assert "move turtlebot to A" in page and "fly to the roof" in page
    assert "interpreted +12" in page and "finished +3000" in page
    page = client.get(reverse("history"), {"status": "needs_user"}).content.decode()
    assert "fly to the roof" in page and "move turtlebot to A" not in page
    page = client.get(reverse("history"), {"robot": "turtlebot"}).content.decode()
    assert "move turtlebot to A" in page and "fly to the roof" not in page


def test_audit_page_is_for_admins_only(client_for, viewer, operator, fleet_admin, fleet):
    leases.take(operator, fleet["turtlebot"])
    assert client_for(viewer).get(reverse("audit")).status_code == 403
    assert client_for(operator).get(reverse("audit")).status_code == 403
    page = client_for(fleet_admin).get(reverse("audit"), {"action": "control"}).content.decode()
    assert "control.take" in page and "otto" in page


def test_audit_link_only_in_the_admin_menu(client_for, operator, fleet_admin, db):
    assert 'href="/audit/"' not in client_for(operator).get("/").content.decode()
    assert 'href="/audit/"' in client_for(fleet_admin).get("/").content.decode()


def test_robot_page_facts_are_words_not_python(client_for, viewer, fleet):
    robot = fleet["turtlebot"]
    robot.description = {
        "wheel_joints": ["wheel_left_joint", "wheel_right_joint"], "urdf_error": "", "drive": "wheeled",
        "wheel_count": 2, "limits_source": "catalog", "footprint": [[0.1, 0.1]], "joint_count": 3,
    }  # fmt: skip
    robot.drive = "wheeled"
    robot.save()
    page = client_for(viewer).get(reverse("robot-detail", args=[robot.pk])).content.decode()
    facts = page[page.index('id="facts-title"') : page.index('id="bindings-title"')]
    assert "<dt>Wheel joints</dt><dd>wheel_left_joint, wheel_right_joint</dd>" in facts
    assert "<dt>Joints</dt><dd>3</dd>" in facts
    assert "[" not in facts and "urdf" not in facts.lower()  # no Python lists, no empty URDF problem
    assert facts.lower().count("<dt>drive</dt>") == 1


def test_robot_page_names_its_camera_and_scan_topics(client_for, viewer, fleet):
    robot = fleet["turtlebot"]
    robot.topics.create(name="/camera/image/compressed", type="sensor_msgs/CompressedImage")
    robot.topics.create(name="/scan", type="sensor_msgs/LaserScan")
    page = client_for(viewer).get(reverse("robot-detail", args=[robot.pk])).content.decode()
    assert 'id="camera"' in page and "<code>/camera/image/compressed</code>" in page
    assert "laser scan <code>/scan</code>" in page
    plain = client_for(viewer).get(reverse("robot-detail", args=[fleet["husky"].pk])).content.decode()
    assert 'id="camera"' not in plain


def test_every_page_links_to_recordings_in_the_navigation(client_for, viewer, fleet):
    client = client_for(viewer)
    for path in ("/", "/robots/", "/history/", "/experiments/", "/recordings/"):
        nav = client.get(path).content.decode().split('<nav aria-label="Main">')[1].split("</nav>")[0]
        assert 'href="/recordings/"' in nav, path
    assert 'href="/recordings/" aria-current="page"' in client.get("/recordings/").content.decode()
