"""Recording the fleet to MCAP: what the portal pushes lands in the file with ROS 2 schemas, read back with mcap's
own reader; `manage.py record` writes one; the page starts one and serves it for replay and download."""

import asyncio
import time

import pytest
from channels.layers import get_channel_layer
from django.core.management import CommandError, call_command
from mcap.reader import make_reader

import live
from recordings import recorder
from recordings.mcapfile import read_messages, replay_frames
from recordings.models import Recording

pytestmark = [pytest.mark.django_db(transaction=True), pytest.mark.timeout(60)]


def _pushes(fleet) -> list[tuple[str, dict]]:
    """What the portal pushes while the turtlebot drives 0.4 m along x: 5 pose ticks, its state, an instruction,
    its goal, an alert."""
    turtlebot, husky = fleet["turtlebot"], fleet["husky"]
    now = time.time()
    ticks = [
        live.poses(
            [
                {
                    "id": turtlebot.pk,
                    "x": 0.1 * i,
                    "y": 0.5,
                    "yaw": 0.0,
                    "v": 0.2,
                    "w": 0.0,
                    "t": now + 0.1 * i,
                },
                {"id": husky.pk, "x": 2.0, "y": 1.0, "yaw": 1.57, "v": 0.0, "w": 0.0, "t": now + 0.1 * i},
            ]
        )
        for i in range(5)
    ]
    events = [
        (live.FLEET_GROUP, {"type": "instruction.update", "id": 7, "text": "move turtlebot to B", "status": "running", "outcome": ""}),
        (live.FLEET_GROUP, {"type": "robot.transition", "robot": "turtlebot", "id": turtlebot.pk, "from_state": "ready", "to_state": "motion", "at": "", "reason": "instruction 7", "instruction": 7}),
        (live.FLEET_GROUP, {"type": "robot.goal", "id": turtlebot.pk, "robot": "turtlebot", "name": "B", "x": 0.8, "y": 0.8}),
        (live.ALERTS_GROUP, {"type": "alert.update", "alert": {"id": 3, "kind": "robot_stuck", "severity": "warning", "robot": "turtlebot", "message": "blocked", "status": "open", "count": 1}, "open_count": 1}),
    ]  # fmt: skip
    return [(live.POSES_GROUP, tick) for tick in ticks] + events


def _record_while_pushing(path, pushes, seconds=1.5) -> dict:
    async def scenario():
        ready = asyncio.Event()
        recording = asyncio.create_task(recorder.record(path, seconds, (), ready))
        await ready.wait()
        layer = get_channel_layer()
        for group, payload in pushes:
            await layer.group_send(group, payload)
        return await recording

    return asyncio.run(scenario())


def test_a_recording_holds_what_the_portal_pushed_with_ros2_schemas(fleet, tmp_path):
    path = tmp_path / "run.mcap"
    # one recording after another in one process, each on a loop of its own (as a worker runs them)
    assert _record_while_pushing(tmp_path / "first.mcap", _pushes(fleet))["/fleet/turtlebot/pose"] == 5
    counts = _record_while_pushing(path, _pushes(fleet))
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    schemas = {schema.name: schema.encoding for schema in summary.schemas.values()}
    assert schemas["geometry_msgs/msg/PoseStamped"] == "ros2msg"
    assert {"fleet_msgs/msg/StateTransition", "fleet_msgs/msg/Instruction", "fleet_msgs/msg/Alert"} <= set(
        schemas
    )
    channels = {c.id: c for c in summary.channels.values()}
    assert {c.message_encoding for c in channels.values()} == {"cdr"}
    in_file = {channels[cid].topic: n for cid, n in summary.statistics.channel_message_counts.items()}
    assert (
        in_file
        == counts
        == {
            "/fleet/turtlebot/pose": 5,
            "/fleet/husky/pose": 5,
            "/fleet/instructions": 1,
            "/fleet/state": 1,
            "/fleet/goals": 1,
            "/fleet/alerts": 1,
        }
    )
    # decoded with mcap-ros2-support's decoder: the turtlebot's path and the state change as pushed
    xs = [m.pose.position.x for topic, _, _, m in read_messages(path) if topic == "/fleet/turtlebot/pose"]
    assert xs == pytest.approx([0.0, 0.1, 0.2, 0.3, 0.4])
    state = next(m for topic, _, _, m in read_messages(path) if topic == "/fleet/state")
    assert (state.robot, state.from_state, state.to_state, state.instruction) == (
        "turtlebot",
        "ready",
        "motion",
        7,
    )
    frames = replay_frames(path)
    assert [pose[1] for pose in frames["robots"]["turtlebot"]] == pytest.approx(xs)
    assert frames["duration"] >= 0.4 and any("ready → motion" in e["text"] for e in frames["events"])


def test_a_long_recording_is_thinned_for_the_page_not_in_the_file(tmp_path, monkeypatch):
    from recordings import mcapfile

    monkeypatch.setattr(mcapfile, "MAX_REPLAY_POSES", 10)
    writer = mcapfile.RecordingWriter(tmp_path / "long.mcap")
    for i in range(95):
        writer.pose("turtlebot", 0.01 * i, 0.0, 0.0, 1000.0 + 0.1 * i)
    assert writer.close() == {"/fleet/turtlebot/pose": 95}
    poses = replay_frames(tmp_path / "long.mcap")["robots"]["turtlebot"]
    assert len(poses) <= 11 and poses[0][1] == 0.0 and poses[-1][1] == pytest.approx(0.94)


def test_manage_py_record_writes_a_file_and_says_what_it_holds(fleet, tmp_path, capsys):
    out = tmp_path / "cli.mcap"
    call_command("record", seconds=0.5, out=out)
    said = capsys.readouterr().out
    assert f"wrote {out}" in said
    recording = Recording.objects.get()
    assert recording.status == "finished" and recording.path == str(out)
    with open(out, "rb") as f:
        assert "fleet_msgs/msg/Alert" in {s.name for s in make_reader(f).get_summary().schemas.values()}
    with pytest.raises(CommandError, match="no Twist topic /odom"):
        call_command("record", seconds=1, out=out, topic=["turtlebot:/odom"])
    with pytest.raises(CommandError, match="seconds"):
        call_command("record", seconds=0, out=out)


def test_the_page_starts_a_recording_and_serves_it(
    fleet, operator, viewer, client_for, monkeypatch, settings, tmp_path
):
    from recordings import tasks

    settings.VAR_DIR = tmp_path  # the file goes to <var>/recordings/
    started = []
    monkeypatch.setattr(tasks.record, "delay", started.append)
    client = client_for(operator)
    client.post("/recordings/", {"seconds": "2", "raw": ["turtlebot:/cmd_vel"]})
    recording = Recording.objects.get()
    assert started == [recording.pk] and recording.raw_topics == ["turtlebot:/cmd_vel"]
    assert recording.path == str(tmp_path / "recordings" / f"recording-{recording.pk}.mcap")
    assert client.get(f"/recordings/{recording.pk}/").status_code == 404  # no file yet
    # as the worker would: record (nothing pushed), then the page replays and downloads it
    Recording.objects.filter(pk=recording.pk).update(raw_topics=[])
    recorder.run(recording.pk)
    client = client_for(viewer)
    assert client.get(f"/recordings/{recording.pk}/").status_code == 200
    assert client.get(f"/recordings/{recording.pk}/frames.json").json()["robots"] == {}
    download = client.get(f"/recordings/{recording.pk}/recording.mcap")
    assert (
        download["Content-Disposition"].startswith("attachment")
        and b"".join(download.streaming_content)[1:5] == b"MCAP"
    )
    assert client.post("/recordings/", {"seconds": "2"}).status_code == 403  # viewers only watch


def test_a_replay_at_its_start_shows_every_robots_pose(fleet, tmp_path):
    """The husky stands still (its pose comes later, or not at all in the recording's seconds): the recording
    starts with every robot's last pose, so at t = 0 the replay shows both robots, not only the first to move."""

    from robots.poses import forget_poses, store_poses

    turtlebot, husky = fleet["turtlebot"], fleet["husky"]
    store_poses([{"id": husky.pk, "x": 2.0, "y": 1.0, "yaw": 1.57, "t": time.time()}])
    try:
        pushes = [p for p in _pushes(fleet) if p[0] == live.POSES_GROUP]
        for _, tick in pushes:  # taken after the recording began, as the links process's poses are
            tick["poses"] = [{**p, "t": p["t"] + 1.0} for p in tick["poses"] if p["id"] == turtlebot.pk]
        pushes.append((live.POSES_GROUP, live.poses([{"id": turtlebot.pk, "fault": "x is NaN"}])))
        path = tmp_path / "start.mcap"
        _record_while_pushing(path, pushes)
    finally:
        forget_poses([robot.pk for robot in fleet.values()])
    frames = replay_frames(path)
    assert frames["robots"]["husky"][0][1:3] == pytest.approx([2.0, 1.0])
    first = {name: poses[0][0] for name, poses in frames["robots"].items()}
    assert first["husky"] <= first["turtlebot"]  # there from the first instant
    assert len(frames["robots"]["turtlebot"]) == 5  # a pose refused at the gate (no place) is not recorded


def test_a_gap_in_the_live_pushes_is_marked_in_the_recording(tmp_path):
    """The channel layer's subscription was cut and taken again (fleet.channel_layer): the pushes in between are
    lost, and the recording says so where it happened instead of looking whole."""
    from recordings import mcapfile

    writer = mcapfile.RecordingWriter(tmp_path / "gap.mcap")
    asyncio.run(recorder._write(writer, {"type": live.RESUBSCRIBED}, {}))
    writer.close()
    [(topic, _, _, alert)] = list(read_messages(tmp_path / "gap.mcap"))
    assert topic == "/fleet/alerts" and alert.kind == recorder.GAP and "missing" in alert.message
    [event] = replay_frames(tmp_path / "gap.mcap")["events"]  # and the replay page says it in its events
    assert event["text"].startswith(f"alert {recorder.GAP} fleet: the live pushes' connection")
