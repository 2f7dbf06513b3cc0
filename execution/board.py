"""What an executor process's robots read from and keep in Redis, in one round trip per tick for all of them.

Each robot the process runs holds its lock through a Lease. Every TICK_S the board sends one MGET: each
lease's stop, preempt and cancel flags (a robot's session reads them from its lease, with no I/O, before every
command). The robots' poses, kept now and then for the fleet (robots.poses), leave in one batch per tick too. So
a driven robot costs its process no Redis call of its own per control tick, and no thread.

The renewals go from one thread of the board's own, every HEARTBEAT_S in one script run: each lease whose command
loop beat within LIVELY_S. On the loop they waited behind everything else the loop does: an executor starting 50
robots at once (an instruction to all of them, bench.cluster) had its round trips take 100 to 470 ms, and with
renewals due every HEARTBEAT_S the locks' one-second time to live ran out, so the watchdog called the executor
lost and the instruction failed. The thread needs the interpreter's lock only for a moment, every HEARTBEAT_S.

What a lease says, as the threaded heartbeat said before it (execution.coordination):
- `held`: the lock was confirmed within its time to live and never refused. A killed or frozen process renews
  nothing, so its locks lapse within LOCK_TTL_MS and the watchdog stops its robots; a command loop that hangs
  in a live process stops beating, and LIVELY_S later its lease is no longer renewed, with the same result.
- `error`: the last read failed (Redis away, or refusing writes): no stop can be seen, so the session stops
  its robot at once with the reason.
- `flags`: (time of the robot's last stop, the preempting execution, the watched execution's cancel words),
  as of the last read. Whoever raises a flag also publishes on coordination's `flags` channel, which the board
  listens to: it reads at once, so a stop is seen one round trip after its flag, not up to TICK_S later (a
  robot under way could otherwise take a command after the stop's zero). TICK_S bounds it when a message is
  lost. A read whose flags differ from the last wakes the lease's session (`wake`, the robot's link: it waits for
  its next odometry), which checks them at once instead of at its next pose: a stop is acted on one round trip
  after its flag, whatever the odometry's rate. A stop's own zeros leave before its flags (execution.fast_stop),
  and a session that sees the flag ends with a zero of its own, so the robot ends at rest either way.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import threading
import time
from collections.abc import Callable

import redis
import redis.asyncio
from django.conf import settings
from redis.exceptions import RedisError, ResponseError

from execution import blocking
from execution.coordination import (
    HEARTBEAT_S,
    LIVELY_S,
    RELEASE,
    RENEW_MANY,
    RobotLock,
    key,
    presence_channel,
    process_name,
)
from fleetcore import faults
from robots import poses as pose_store

TICK_S = 0.05  # between the board's round trips: a flag is seen this late at most when its nudge is lost
REDIS_TIMEOUT_S = 0.5  # one round trip; a Redis that does not answer is an error for every lease at once
LISTEN_RETRY_S = 1.0  # the flags channel's subscription, lost, is made again after this

log = logging.getLogger(__name__)


class NoAnswer(RedisError):
    """The flags' read got no answer within its bound: Redis, or this process, too busy to tell which (an executor
    starved of CPU reads its answers late too). Not "Redis unreachable": it may well be up."""


def _read_failure(exc: BaseException) -> RedisError:
    """What a failed read of the flags says: NoAnswer for a timeout, the Redis error itself, else unreachable."""
    if isinstance(exc, TimeoutError | redis.exceptions.TimeoutError):
        return NoAnswer(f"no answer within {REDIS_TIMEOUT_S * 2:g} s: Redis or this executor too busy")
    return exc if isinstance(exc, RedisError) else RedisError(f"no answer from Redis ({exc})")


class Lease:
    """A robot lock this process holds, kept by its board (renewed while the command loop beats)."""

    def __init__(self, lock: RobotLock, lively: float = LIVELY_S) -> None:
        self.lock, self.lively = lock, lively
        self.renewed = self.alive_until = time.monotonic()
        self.lost = self.quiet = False  # written by the board's renewals thread, read on the loop
        self.taken = False  # the lock seen released or held by another token (the flags' read)
        self.fault: str | None = None  # why Redis refused a renewal's write (a full disk), in words
        self.error: RedisError | None = None  # the last read's failure, until a read succeeds
        self.watched: int | None = None  # the execution whose cancel flag is read
        self.flags: tuple[float, int | None, str | None] = (0.0, None, None)
        self.pose: tuple | None = None  # to keep for the fleet with the next tick
        self.wake: Callable[[], None] | None = None  # the session's, called when the flags change
        self._read = asyncio.Event()
        self.beat()

    @property
    def token(self) -> str:
        return self.lock.token

    def beat(self, lively: float | None = None) -> None:
        """The command loop is alive: keep renewing for another LIVELY_S (or `lively` s: a wait of its own while
        its robot rests, such as the database recording its end: execution.runner.while_resting)."""
        self.window = self.lively if lively is None else lively
        self.alive_until = time.monotonic() + self.window

    @property
    def held(self) -> bool:
        """Whether the lock is still ours: never refused, and confirmed within its time to live."""
        return not self.lost and time.monotonic() - self.renewed < self.lock.ttl_ms / 1000

    @property
    def why_lost(self) -> str:
        """Why the lock is not ours, in a person's words (for the execution's outcome)."""
        if self.fault:
            return f"{self.fault}, so its lock on the robot could not be kept"
        if self.quiet:  # its own loop stopped: the lock lapsed, whoever saw it gone first
            return self.why_quiet
        if self.taken:
            return "its lock on the robot was released by another (it is not ours any more)"
        if self.lost:
            return "its lock on the robot lapsed before it was renewed (it is not ours any more)"
        return f"its lock on the robot was not renewed for {self.lock.ttl_ms / 1000:g} s (a starved process?)"

    @property
    def why_quiet(self) -> str:
        return f"its command loop did not run for {self.window:g} s, so its lock on the robot lapsed"

    def watch(self, execution_id: int) -> None:
        """Read this execution's cancel flag from now on (the execution the robot runs)."""
        self.watched, self.flags = execution_id, (self.flags[0], self.flags[1], None)

    def keep_pose(self, pose) -> None:
        self.pose = pose

    async def fresh(self, timeout: float = 2.0) -> None:
        """Wait for the board's next read (flags as of now, not as of before this call)."""
        self._read.clear()
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(self._read.wait(), timeout)

    def _renewed(self, renewed, sent: float) -> None:
        """The answer of a renewal sent at `sent` (the renewals thread)."""
        if isinstance(renewed, ResponseError):
            self.fault = faults.refusal(renewed) or str(renewed)
            self.lost = True
        elif isinstance(renewed, Exception):
            return  # not renewed this time: the next may still come in time
        elif renewed:
            self.renewed = sent
        else:
            self.lost = True

    def _took(self, values) -> None:
        """The flags of one round trip, and the lock's holder."""
        stop, preempt, cancel, holder = values
        if holder is None or holder.decode() != self.token:
            self.lost = self.taken = True  # released, or taken, by another: not ours to drive any more
        flags = (float(stop) if stop else 0.0, int(preempt) if preempt else None,
                 cancel.decode() if cancel else None)  # fmt: skip
        changed, self.flags, self.error = flags != self.flags, flags, None
        self._read.set()
        if changed and self.wake is not None:
            self.wake()

    def _failed(self, exc: RedisError) -> None:
        self.error = exc
        self._read.set()


class Board:
    """The process's one Redis round trip per tick for all its leases (see the module's docstring)."""

    def __init__(self, tick: float = TICK_S, every: float = HEARTBEAT_S) -> None:
        self.tick, self.every = tick, every
        self.leases: set[Lease] = set()
        self._client: redis.asyncio.Redis | None = None
        self._storing: asyncio.Future | None = None
        self._nudged = asyncio.Event()  # a flag was raised somewhere: read now
        # a lease was taken: what an idle board waits for. Not a nudge: 250 robots started together then each
        # made a read of every lease's flags, back to back, and the executors' locks lapsed under the load
        # ("executor lost" for 125 of 500 robots, bench.cluster)
        self._leased = asyncio.Event()
        # subscribed to this process's presence channel (coordination.present)
        self._present = asyncio.Event()

    def lease(self, lock: RobotLock, lively: float = LIVELY_S) -> Lease:
        """Keep this acquired lock from now on (renewed while its command loop beats)."""
        lease = Lease(lock, lively)
        self.leases.add(lease)
        self._leased.set()  # an idle board wakes: the first lease's flags are read at once
        return lease

    def drop(self, lease: Lease) -> None:
        self.leases.discard(lease)

    async def take(self, lock: RobotLock) -> Lease | None:
        """Acquire the lock in one round trip on the loop and keep it from now on; None: someone holds it.
        (Through the robots' blocking pool, an executor starting 50 robots queued each acquire behind the
        others' database calls.) Only once this process is present (the watchdog takes a lock holder that is
        not as gone); no presence or no answer within its bound raises: the lock, if it was set, lapses."""
        if not self._present.is_set():  # (wait_for makes a task: not for every robot's start once present)
            await asyncio.wait_for(self._present.wait(), REDIS_TIMEOUT_S * 2)
        taken = self._redis().set(lock.key, lock.token, nx=True, px=lock.ttl_ms)
        return self.lease(lock) if await asyncio.wait_for(taken, REDIS_TIMEOUT_S * 2) else None

    async def give_back(self, lease: Lease) -> None:
        """Stop keeping the lease and release its lock (Redis away: it lapses within its time to live)."""
        self.drop(lease)
        with contextlib.suppress(RedisError, OSError, TimeoutError):
            release = self._redis().eval(RELEASE, 1, lease.lock.key, lease.token)
            await asyncio.wait_for(release, REDIS_TIMEOUT_S * 2)

    async def run(self) -> None:
        """Tick until cancelled, at once when a flag is raised or a lease is taken, not at all while there is no
        lease; the renewals' thread meanwhile."""
        listening = asyncio.ensure_future(self._listen())
        ended = threading.Event()
        threading.Thread(target=self._renewals, args=(ended,), name="executor renewals", daemon=True).start()
        try:
            while True:
                started = time.monotonic()
                self._nudged.clear()
                await self.once()
                if not self.leases:  # nothing to read until a lease is taken: no tick (an idle executor
                    self._leased.clear()  # woke 20 times a second for nothing)
                    await self._leased.wait()
                    continue
                with contextlib.suppress(TimeoutError):
                    await asyncio.wait_for(
                        self._nudged.wait(), max(0.0, self.tick - (time.monotonic() - started))
                    )
        finally:
            ended.set()
            listening.cancel()
            if self._client is not None:
                with contextlib.suppress(Exception):  # closing a link to a Redis that is away
                    await self._client.aclose()

    async def once(self) -> None:
        """One round trip: every lease's flags; then the poses kept since the last tick."""
        leases = list(self.leases)
        if not leases:
            return
        # one MGET for every lease's three flags: a pipeline of an MGET each was a tenth of an executor driving 50
        # robots (py-spy), its Python per command twenty times a second
        # and its lock's holder: a lock released by another (the watchdog, taking this process for gone when only
        # its presence connection was cut) is seen at the next tick, not at the next renewal (0.25 s of commands
        # more: 0.038 m in a CI run)
        keys = []
        for lease in leases:
            robot = lease.lock.robot_id
            cancel = key("cancel", lease.watched) if lease.watched is not None else key("cancel", "none")
            keys += [key("stop", robot), key("preempt", robot), cancel, lease.lock.key]
        try:
            values = await asyncio.wait_for(self._redis().mget(keys), REDIS_TIMEOUT_S * 2)
        except (RedisError, OSError, TimeoutError) as exc:
            error = _read_failure(exc)
            for lease in leases:
                lease._failed(error)
            return
        for index, lease in enumerate(leases):
            lease._took(values[4 * index : 4 * index + 4])
        self._store_poses(leases)

    def _renewals(self, ended: threading.Event) -> None:
        """The renewals thread: every `every`, renew each lease whose command loop beat, in one script run, until
        the board ends (a Redis that fails a round trip is tried again next time; the flags' reads say it)."""
        client = redis.Redis.from_url(
            settings.REDIS_URL, socket_timeout=REDIS_TIMEOUT_S, socket_connect_timeout=REDIS_TIMEOUT_S
        )
        try:
            while not ended.wait(self.every):
                with contextlib.suppress(RedisError, OSError):
                    self.renew(client)
        finally:
            client.close()

    def renew(self, client: redis.Redis) -> None:
        """One script renewing every lease that is neither quiet (its command loop has not beaten within its
        lively time: hung) nor lost (a pipeline of a script run per lease was 250 runs four times a second for an
        executor driving 250 robots, its thread holding the interpreter's lock for each). A Redis refusing the
        write refuses it for every lease."""
        now = time.monotonic()
        due = []
        for lease in list(self.leases):  # one C call: safe while the loop adds and drops leases
            quiet = now > lease.alive_until
            if quiet and not lease.quiet:
                log.warning("robot %s: %s", lease.lock.robot_id, lease.why_quiet)
            lease.quiet = quiet
            if not lease.quiet and not lease.lost:
                due.append(lease)
        if not due:
            return
        tokens = [value for lease in due for value in (lease.token, lease.lock.ttl_ms)]
        try:
            answers = client.eval(RENEW_MANY, len(due), *(lease.lock.key for lease in due), *tokens)
        except ResponseError as exc:  # refused (a full disk, read-only): no lease renewed, each told why
            answers = [exc] * len(due)
        for lease, renewed in zip(due, answers, strict=True):
            lease._renewed(renewed, now)

    async def _listen(self) -> None:
        """Nudge the loop on every message of the flags channel; a lost subscription is made again (the ticks
        go on meanwhile). The same connection holds this process's presence: subscribed to its channel, and
        named after it too (CLIENT LIST shows which executors are present; a test cuts just this one)."""
        presence = presence_channel(process_name())
        client = redis.asyncio.Redis.from_url(
            settings.REDIS_URL, socket_connect_timeout=REDIS_TIMEOUT_S, client_name=presence
        )
        try:
            while True:
                try:
                    async with client.pubsub() as pubsub:
                        await pubsub.subscribe(key("flags"), presence)
                        while True:
                            message = await pubsub.get_message(ignore_subscribe_messages=True, timeout=None)
                            if message is not None:
                                self._nudged.set()
                            else:  # a confirmation: Redis registered both channels before answering
                                self._present.set()
                except (RedisError, OSError):  # Redis away: the ticks see it too; subscribe again later
                    self._present.clear()
                    await asyncio.sleep(LISTEN_RETRY_S)
        finally:
            with contextlib.suppress(Exception):  # closing a link to a Redis that is away
                await client.aclose()

    def _store_poses(self, leases: list[Lease]) -> None:
        """The poses kept since the last tick, in one batch off the loop (one batch in flight at a time)."""
        if self._storing is not None and not self._storing.done():
            return
        batch = []
        for lease in leases:
            if lease.pose is not None:
                x, y, yaw = lease.pose
                batch.append({"id": lease.lock.robot_id, "x": round(x, 3), "y": round(y, 3), "yaw": round(yaw, 4),
                              "t": time.time()})  # fmt: skip
                lease.pose = None
        if batch:
            self._storing = asyncio.ensure_future(_store(batch))

    def _redis(self) -> redis.asyncio.Redis:
        if self._client is None:
            self._client = redis.asyncio.Redis.from_url(
                settings.REDIS_URL, socket_timeout=REDIS_TIMEOUT_S, socket_connect_timeout=REDIS_TIMEOUT_S
            )
        return self._client


async def _store(batch: list[dict]) -> None:
    try:
        await blocking.call(pose_store.store_poses, batch)
    except Exception:  # the cache is away: the pose hub (or the next tick) keeps them later
        log.warning("executor: %d poses could not be kept", len(batch), exc_info=True)


_boards: dict[asyncio.AbstractEventLoop, Board] = {}


def of_loop() -> Board:
    """The running loop's board, started on first use (one per executor process: one loop)."""
    loop = asyncio.get_running_loop()
    board = _boards.get(loop)
    if board is None:
        board = _boards[loop] = Board()
        task = loop.create_task(board.run(), name="executor board")
        task.add_done_callback(lambda _: _boards.pop(loop, None))
    return board
