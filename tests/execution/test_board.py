"""The executor's board: a robot's lock renewed while its command loop beats and lapsed when it does not, and
the flags every session reads from its lease, all in one Redis round trip per tick for the process."""

import asyncio
import time
import uuid

import pytest
import redis

from execution import coordination
from execution.board import Board
from execution.link import Latest


@pytest.fixture
def lock(settings):
    settings.FLEET_EXEC_KEY_PREFIX = f"test:board:{uuid.uuid4().hex[:8]}"
    lock = coordination.RobotLock(1, ttl_ms=400)
    assert lock.acquire()
    yield lock
    lock.release()


def on_board(body, tick: float = 0.02, every: float = 0.05):
    """Run body(board) on a fresh loop with the board ticking beside it."""

    async def main():
        board = Board(tick=tick, every=every)
        ticking = asyncio.ensure_future(board.run())
        try:
            return await body(board)
        finally:
            ticking.cancel()

    return asyncio.run(main())


def reads_of(monkeypatch) -> list[tuple[float, int]]:
    """(when, how many leases) of each read of the flags a board makes from now on."""
    reads, once = [], Board.once

    async def counted(board):
        reads.append((time.monotonic(), len(board.leases)))
        await once(board)

    monkeypatch.setattr(Board, "once", counted)
    return reads


def test_a_board_with_no_lease_does_not_tick_and_a_lease_is_read_at_once(lock, monkeypatch):
    """An executor driving nothing has no flags to read: its board waits for a lease instead of waking every
    tick (each idle executor cost about a hundredth of a core), and a lease taken is read at once, not at the
    next tick."""
    rounds = reads_of(monkeypatch)

    async def idle(board):
        await asyncio.sleep(0.3)  # 15 ticks of 0.02 s, were it ticking

    on_board(idle, tick=0.02)
    assert len(rounds) <= 1  # the one look at start-up

    async def leased(board):
        await asyncio.sleep(0.05)
        taken_at = time.monotonic()
        board.lease(lock, lively=5.0).beat()
        await asyncio.sleep(0.3)
        return taken_at

    rounds.clear()
    taken_at = on_board(leased, tick=10.0)  # a tick later would be seconds later
    assert [leases for _, leases in rounds] == [0, 1]
    assert rounds[1][0] - taken_at < 0.3


def test_robots_started_together_cost_their_board_no_read_each(monkeypatch):
    """An executor starting 250 robots takes their leases one round trip after another. Each lease woke the board
    for a read of every lease's flags, back to back, and under that load the executors' locks lapsed ("executor
    lost" for 125 of 500 robots, bench.cluster): only an idle board wakes for a lease, the others wait their tick."""
    rounds = reads_of(monkeypatch)

    async def started_together(board):
        await asyncio.sleep(0.05)
        for robot_id in range(1, 21):
            lock = coordination.RobotLock(robot_id, ttl_ms=60_000)
            board.lease(lock, lively=5.0).beat()
            await asyncio.sleep(0.005)  # the next robot's lock: a round trip later
        await asyncio.sleep(0.1)

    on_board(started_together, tick=10.0)
    assert rounds[0][1] == 0 and len(rounds) <= 3  # start-up, the first lease's wake (a tick is 10 s)


def test_a_beating_command_loop_keeps_the_lock_past_its_time_to_live(lock):
    async def body(board):
        lease = board.lease(lock, lively=1.0)
        for _ in range(16):  # 0.8 s: twice the lock's time to live
            lease.beat()
            await asyncio.sleep(0.05)
        return lease.held

    assert on_board(body)
    assert coordination.lock_holders([1])[1] == lock.token


def test_the_locks_are_renewed_while_the_loop_is_busy_longer_than_their_time_to_live(lock):
    """An executor's loop busy for longer than a lock's time to live still keeps its locks: the renewals have a
    thread of their own (50 robots starting at once kept the loop's round trips waiting 100 to 470 ms, and their
    one-second locks lapsed: executor lost, bench.cluster)."""

    async def body(board):
        lease = board.lease(lock, lively=2.0)
        await asyncio.sleep(0.1)
        time.sleep(0.8)  # the loop held: twice the lock's time to live, nothing of it runs
        return lease.held

    assert on_board(body)
    assert coordination.lock_holders([1])[1] == lock.token


def test_a_hung_command_loop_lets_the_lock_lapse_for_the_watchdog(lock):
    async def body(board):
        lease = board.lease(lock, lively=0.1)
        await asyncio.sleep(
            0.8
        )  # no beat: after 0.1 s the board stops renewing, 0.4 s later the lock is gone
        return lease

    lease = on_board(body)
    assert coordination.lock_holders([1])[1] is None
    assert not lease.held and lease.quiet  # the loop, if it ever wakes, sends nothing more
    assert "did not run for 0.1 s" in lease.why_lost


def test_a_lock_taken_by_another_is_lost_for_good(lock):
    async def body(board):
        lease = board.lease(lock, lively=5.0)
        coordination.connection().set(lock.key, "someone-else")
        await asyncio.sleep(0.2)
        return lease

    lease = on_board(body)
    assert lease.lost and not lease.held


def test_a_lock_released_by_another_is_seen_at_the_next_tick_not_the_next_renewal(settings):
    """The watchdog releases the lock of a holder whose process it takes for gone; a holder alive (only its
    presence connection cut) drove on until its next renewal told it (0.25 s: 0.038 m in a CI run). The flags'
    read, every tick, carries the lock's holder; renewals here come every 5 s, so only that read can tell."""
    settings.FLEET_EXEC_KEY_PREFIX = f"test:board:{uuid.uuid4().hex[:8]}"
    lock = coordination.RobotLock(1, ttl_ms=10_000)
    assert lock.acquire()

    async def body(board):
        lease = board.lease(lock, lively=10.0)
        await asyncio.sleep(0.1)
        held_before = lease.held
        coordination.RobotLock(1, lock.token).release()  # as the watchdog does (execution.watchdog)
        started = time.monotonic()
        while lease.held and time.monotonic() - started < 2.0:
            lease.beat()
            await asyncio.sleep(0.005)
        return held_before, lease, time.monotonic() - started

    held_before, lease, took = on_board(body, tick=0.05, every=5.0)
    assert held_before and not lease.held and took < 0.5, took
    assert lease.why_lost == "its lock on the robot was released by another (it is not ours any more)"


def test_the_flags_of_every_lease_come_in_one_round_trip_per_tick(lock, monkeypatch):
    other = coordination.RobotLock(2, ttl_ms=400)
    assert other.acquire()
    sent = []

    async def body(board):
        first, second = board.lease(lock), board.lease(other)
        second.watch(77)
        real = board._redis().execute_command

        def counting(*args, **kwargs):
            sent.append(args[0])
            return real(*args, **kwargs)

        monkeypatch.setattr(board._redis(), "execute_command", counting)
        stopped = coordination.request_stop([1])
        coordination.request_cancel([77], "cancelled by ada")
        sent.clear()
        await first.fresh()
        await first.fresh()
        return stopped, first.flags, second.flags, list(sent)

    try:
        stopped, first, second, trips = on_board(body)
    finally:
        other.release()
    assert first[0] == pytest.approx(stopped) and first[2] is None
    assert second == (0.0, None, "cancelled by ada")
    assert 1 <= len(trips) <= 3 and set(trips) == {"MGET"}  # two ticks for two leases: one MGET a tick


def test_redis_lost_under_a_command_loop_fails_the_step_as_executor_lost(lock, monkeypatch):
    """No stop flag, preemption or lock can be seen without Redis: the step ends (its robot is then halted by
    the runner) with a reason a person reads, not a connection error's."""
    from types import SimpleNamespace

    from execution import handlers
    from execution.handlers import run_step
    from execution.steps import REDIS_LOST, Interrupted, Session

    def unreachable(*_args):
        raise redis.ConnectionError("Error 111 connecting to redis.sock. Connection refused.")

    async def body(board):
        lease = board.lease(lock)
        await lease.fresh()
        monkeypatch.setattr(board, "_redis", lambda: _Broken())
        await lease.fresh()
        link = SimpleNamespace(robot=SimpleNamespace(pk=1, name="tb"), poses=Latest())
        session = Session(SimpleNamespace(pk=1), link, lease)
        with pytest.raises(Interrupted) as failure:
            session.check()
        assert failure.value.outcome == "failed" and failure.value.reason.startswith(REDIS_LOST)

        async def go_to(*_args):
            unreachable()

        # a Redis error from anywhere in a step's handler (e.g. releasing its route) says the same
        monkeypatch.setitem(handlers.HANDLERS, "go_to", go_to)
        with pytest.raises(Interrupted) as failure:
            await run_step(
                session, {"action": "move", "robots": ["tb"], "destination": {"name": "X", "x": 1, "y": 0}}
            )
        assert failure.value.reason.startswith(REDIS_LOST)

    on_board(body)


class _Broken:
    """A client of a Redis that is gone."""

    async def mget(self, *_args):
        raise redis.ConnectionError("Error 111 connecting to redis.sock. Connection refused.")


class _Hung(_Broken):
    """A client whose answer never comes in time (Redis, or this process, too busy)."""

    async def mget(self, *_args):
        await asyncio.sleep(60)


def test_a_read_that_gets_no_answer_in_time_fails_the_step_saying_so_not_redis_unreachable(lock, monkeypatch):
    """On a machine out of CPU an executor reads its answers late: its robots stop "executor lost", but the words
    do not blame a Redis that may be up (1,000 robots on the cluster: 57 robots failed "Redis unreachable")."""
    from types import SimpleNamespace

    from execution.steps import REDIS_LATE, REDIS_LOST, Interrupted, Session

    async def body(board):
        lease = board.lease(lock)
        await lease.fresh()
        monkeypatch.setattr(board, "_redis", lambda: _Hung())
        await lease.fresh(timeout=3.0)  # the read's bound (1 s) passes first
        link = SimpleNamespace(robot=SimpleNamespace(pk=1, name="tb"), poses=Latest())
        with pytest.raises(Interrupted) as failure:
            Session(SimpleNamespace(pk=1), link, lease).check()
        return failure.value

    failure = on_board(body)
    assert failure.outcome == "failed" and failure.reason.startswith(REDIS_LATE)
    assert not failure.reason.startswith(REDIS_LOST) and "too busy" in failure.reason


def test_a_stop_flag_is_read_at_once_not_at_the_next_tick(lock):
    """Raising a flag publishes on the flags channel: the board reads then, so a robot under way takes no
    command after a stop for want of a tick (here the ticks are 10 s apart)."""

    async def body(board):
        lease = board.lease(lock)
        await asyncio.sleep(0.3)  # the first tick done, the flags channel subscribed
        raised = coordination.request_stop([1])
        started = time.monotonic()
        while lease.flags[0] != raised and time.monotonic() - started < 5.0:
            await asyncio.sleep(0.005)
        return lease.flags[0] == raised, time.monotonic() - started

    seen, after = on_board(body, tick=10.0, every=10.0)
    assert seen and after < 5.0  # bounded; far under the 10 s tick


def test_a_stop_flag_ends_a_sessions_wait_for_odometry_at_once_not_at_its_next_pose(lock):
    """A session waits for its robot's next odometry between commands (a tick of its control loop). A stop
    raised meanwhile wakes it: it ends "stopped" then (its runner halts the robot), not when the next pose
    comes; here none comes, and without the wake the wait would end "no odometry" after ODOMETRY_TIMEOUT."""
    from types import SimpleNamespace

    from execution.steps import Interrupted, Session

    async def halt():
        return None

    async def body(board):
        lease = board.lease(lock)
        await lease.fresh()
        poses = Latest()
        link = SimpleNamespace(
            robot=SimpleNamespace(pk=1, name="tb", endpoint="ws://127.0.0.1:1"),
            poses=poses,
            fault=None,
            flagged=None,
            connected=True,
            odometry=SimpleNamespace(target="/odom"),
            halt=halt,
            next_pose=lambda seen, timeout, between=None: poses.next(seen, timeout, between),
        )
        session = Session(SimpleNamespace(pk=1), link, lease)
        waiting = asyncio.ensure_future(session.pose())
        await asyncio.sleep(0.3)  # waiting for a pose; the board's flags channel subscribed
        assert not waiting.done()
        coordination.request_stop([1])
        with pytest.raises(Interrupted) as stopped:
            await waiting
        return stopped.value

    stopped = on_board(body, tick=10.0, every=0.05)  # no tick reads the flag: the channel's nudge does
    assert (stopped.outcome, stopped.reason) == ("cancelled", "stopped")


def test_a_wait_in_the_blocking_pool_while_the_robot_rests_keeps_its_lock(lock):
    """A stop-all ends every robot of an executor at once; their ends queue in its blocking pool. One that waited
    past its lively time let its lock lapse, and the watchdog called a robot a person had stopped "executor lost"
    (bench.cluster, 500 robots: 159 of them). A wait while the robot rests keeps the lease beating."""
    from execution.runner import while_resting

    async def body(board):
        lease = board.lease(lock, lively=0.1)
        waited = await while_resting(
            lease, time.sleep, 0.8
        )  # twice the lock's time to live, 8x its lively time
        return lease, waited

    lease, _ = on_board(body)
    assert lease.held and not lease.quiet
    assert coordination.lock_holders([1])[1] == lock.token


def test_a_timing_stamp_does_not_hold_the_control_loop_while_the_database_is_slow(lock, monkeypatch):
    """The first command's stamp goes to the database through the pool; with the pool busy, the loop that commands
    the robot goes on (its next pose, its next command) and the stamp lands later, before the run's end."""
    import threading
    from types import SimpleNamespace

    from execution import steps

    released, stamped = threading.Event(), []

    def slow_stamp(execution, field_name, now):
        assert released.wait(5.0)
        stamped.append((field_name, now))

    monkeypatch.setattr(steps, "_stamp", slow_stamp)

    async def body(board):
        lease = board.lease(lock)
        link = SimpleNamespace(robot=SimpleNamespace(pk=1, name="tb"), poses=Latest())
        session = steps.Session(SimpleNamespace(pk=1), link, lease)
        await session.mark_commanded()  # returns with the stamp still held in the pool
        held = [task.done() for task in session.stamps]
        released.set()
        await session.stamped()
        return held

    assert on_board(body) == [False]
    assert [name for name, _ in stamped] == ["first_command_at"]


def test_every_lease_is_renewed_by_one_script_run_and_told_its_own_answer(lock):
    """The renewals of all an executor's leases go in one script run; each lease reads its own answer: a lock
    another process took is lost for that robot alone."""
    others = [coordination.RobotLock(robot_id, ttl_ms=400) for robot_id in (2, 3)]
    assert all(other.acquire() for other in others)

    async def body(board):
        leases = [board.lease(each, lively=2.0) for each in (lock, *others)]
        coordination.connection().set(others[0].key, "someone-else")
        for _ in range(16):  # 0.8 s: twice the locks' time to live
            for lease in leases:
                lease.beat()
            await asyncio.sleep(0.05)
        return leases

    try:
        mine, taken, kept = on_board(body)
        assert mine.held and kept.held
        assert taken.lost and not taken.held
        assert coordination.lock_holders([1, 2, 3]) == {1: lock.token, 2: "someone-else", 3: others[1].token}
    finally:
        others[1].release()
        coordination.connection().delete(others[0].key)
