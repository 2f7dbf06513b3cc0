"""The heartbeat of a robot's command stream: renewed while the command loop beats, lapsed when it does not."""

import time
import uuid

import pytest

from execution import coordination


@pytest.fixture
def lock(settings):
    settings.FLEET_EXEC_KEY_PREFIX = f"test:hb:{uuid.uuid4().hex[:8]}"
    lock = coordination.RobotLock(1, ttl_ms=400)
    assert lock.acquire()
    yield lock
    lock.release()


def test_a_beating_command_loop_keeps_the_lock_past_its_time_to_live(lock):
    heartbeat = coordination.Heartbeat(lock, every=0.05, lively=1.0).start()
    try:
        for _ in range(16):  # 0.8 s: twice the lock's time to live
            heartbeat.beat()
            time.sleep(0.05)
        assert heartbeat.held and coordination.lock_holders([1])[1] == lock.token
    finally:
        heartbeat.stop()


def test_a_hung_command_loop_lets_the_lock_lapse_for_the_watchdog(lock):
    heartbeat = coordination.Heartbeat(lock, every=0.05, lively=0.1).start()
    try:
        time.sleep(0.8)  # no beat: after 0.1 s the heartbeat stops renewing, 0.4 s later the lock is gone
        assert coordination.lock_holders([1])[1] is None
        assert not heartbeat.held  # the loop, if it ever wakes, sends nothing more
    finally:
        heartbeat.stop()


def test_a_lock_taken_by_another_is_lost_for_good(lock):
    heartbeat = coordination.Heartbeat(lock, every=0.05, lively=5.0).start()
    try:
        coordination.connection().set(lock.key, "someone-else")
        time.sleep(0.2)
        assert heartbeat.lost and not heartbeat.held
    finally:
        heartbeat.stop()


def test_lock_holders_reads_every_robot_in_one_round_trip(lock):
    assert coordination.lock_holders([1, 2]) == {1: lock.token, 2: None}
    assert coordination.lock_holders([]) == {}


def test_redis_lost_under_a_command_loop_fails_the_step_as_executor_lost(lock, monkeypatch):
    """No stop flag, preemption or lock can be seen without Redis: the step ends (its robot is then halted by
    the runner) with a reason a person reads, not a connection error's."""
    from types import SimpleNamespace

    import redis

    from execution import handlers
    from execution.handlers import run_step
    from execution.steps import REDIS_LOST, Interrupted, Session

    def unreachable(*_args):
        raise redis.ConnectionError("Error 111 connecting to redis.sock. Connection refused.")

    heartbeat = coordination.Heartbeat(lock).start()
    link = SimpleNamespace(robot=SimpleNamespace(pk=1, name="tb"), poses=SimpleNamespace(value=None))
    session = Session(SimpleNamespace(pk=1), link, heartbeat)
    monkeypatch.setattr(coordination, "session_flags", unreachable)
    try:
        with pytest.raises(Interrupted) as failure:
            session.check()
        assert failure.value.outcome == "failed" and failure.value.reason.startswith(REDIS_LOST)

        # a Redis error from anywhere in a step's handler (e.g. releasing its route) says the same
        monkeypatch.setitem(handlers.HANDLERS, "go_to", lambda *_args: unreachable())
        with pytest.raises(Interrupted) as failure:
            run_step(
                session, {"action": "move", "robots": ["tb"], "destination": {"name": "X", "x": 1, "y": 0}}
            )
        assert failure.value.reason.startswith(REDIS_LOST)
    finally:
        heartbeat.stop()
