"""The task list and the page's controls in the JSON API: a robot's queue with its progress, moving and cancelling
queued instructions, stop, control leases, poses with telemetry; a viewer refused each call that changes
something (the fuzz and role-matrix tests cover every operation and role; this one follows one flow)."""

import time

import pytest

from execution import queues
from execution.models import Execution, Instruction
from execution.runner import next_execution
from robots.models import Robot
from robots.poses import store_pose

pytestmark = pytest.mark.usefixtures("recorded_control")


@pytest.fixture
def husky(db, settings):
    settings.FLEET_EXEC_KEY_PREFIX = f"test:tasklist:{time.monotonic_ns()}"
    return Robot.objects.create(
        name="husky", model="husky", drive="wheeled", endpoint="ws://127.0.0.1:1", max_linear=1.0
    )


def _queue(robot, user, text, x, status="queued"):
    instruction = Instruction.objects.create(text=text, user=user, status=Instruction.Status.QUEUED)
    Execution.objects.create(
        instruction=instruction, robot=robot, status=status,
        steps=[{"action": "move", "robots": [robot.name], "destination": {"name": text[-1], "x": x, "y": 0.0},
                "task": None, "speed": "normal"}],
    )  # fmt: skip
    return instruction


def test_progress_is_the_distance_left_to_the_goal_at_the_steps_speed():
    step = {"action": "move", "destination": {"name": "B", "x": 3.0, "y": 4.0}, "speed": "slow"}
    assert queues.progress(step, {"x": 0.0, "y": 0.0}, 1.0, 2.0) == {
        "distance_left": 5.0,
        "speed": 0.35,
        "eta_s": 14.3,
    }
    assert queues.progress({"action": "rotate", "destination": None}, {"x": 0.0, "y": 0.0}, 1.0, 2.0) == {}


def test_an_operator_runs_the_task_list_through_the_api_alone(client_for, husky, operator, viewer):
    running = _queue(husky, operator, "move husky to A", 4.0, status="running")
    first, second = (
        _queue(husky, operator, "move husky to B", 1.0),
        _queue(husky, operator, "move husky to C", 2.0),
    )
    store_pose(husky.pk, (1.0, 0.0, 0.0))

    api = client_for(operator)
    queue = api.get("/api/robots/husky/queue").json()
    assert queue["running"]["instruction"] == running.pk
    assert (queue["running"]["step"], queue["running"]["steps"]) == (1, 1)
    assert queue["running"]["distance_left"] == 3.0 and queue["running"]["eta_s"] == 5.0  # 3 m at 0.6 m/s
    assert [(e["instruction"], e["position"]) for e in queue["queued"]] == [(first.pk, 1), (second.pk, 2)]

    moved = api.post(
        f"/api/robots/husky/queue/{second.pk}/move", {"direction": "up"}, content_type="application/json"
    )
    assert [e["instruction"] for e in moved.json()["queued"]] == [second.pk, first.pk]
    assert next_execution(husky.pk).instruction_id == second.pk  # the order the runner takes them in

    cancelled = api.post(f"/api/instructions/{second.pk}/cancel")
    assert cancelled.status_code == 200 and cancelled.json()["status"] == "cancelled"
    assert "cancelled by otto" in cancelled.json()["outcome"]
    again = api.post(f"/api/instructions/{second.pk}/cancel")
    assert again.status_code == 409 and again.json()["detail"].startswith("instruction_id: ")

    robots = api.get("/api/robots").json()
    pose = next(r for r in robots if r["name"] == "husky")["pose"]
    assert (pose["x"], pose["y"]) == (1.0, 0.0) and "v" in pose and "battery" in pose

    lease = api.post("/api/robots/husky/lease").json()
    assert lease["holder"] == "otto" and lease["expires_at"]
    assert api.delete("/api/robots/husky/lease").json()["holder"] is None

    stop = api.post("/api/stop", {"robots": ["husky"]}, content_type="application/json")
    assert stop.status_code == 200 and "husky: stopped" in stop.json()["outcome"], stop.json()
    assert api.post("/api/stop", {"robots": ["wall-e"]}, content_type="application/json").status_code == 422


def test_a_viewer_is_refused_each_call_that_changes_something(client_for, husky, operator, viewer):
    queued = _queue(husky, operator, "move husky to B", 1.0)
    api = client_for(viewer)
    assert api.get("/api/robots/husky/queue").status_code == 200
    calls = [
        api.post(f"/api/instructions/{queued.pk}/cancel"),
        api.post(
            f"/api/robots/husky/queue/{queued.pk}/move", {"direction": "up"}, content_type="application/json"
        ),
        api.post("/api/stop", {}, content_type="application/json"),
        api.post("/api/robots/husky/lease"),
        api.delete("/api/robots/husky/lease"),
    ]
    assert [call.status_code for call in calls] == [403] * 5
    queued.refresh_from_db()
    assert queued.status == "queued"
