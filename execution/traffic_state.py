"""The shared state of traffic, in Redis where every worker sees it, behind one narrow interface: the plans
(reserved cells, timed paths, routes for the map), the claims (checked and written in one WATCH transaction),
the waits and the deadlocks broken, the turn to plan, the requests to make way, and nav stacks' paces.

It keeps and reads; it decides nothing of the algorithm (fleetcore.traffic decides, execution.traffic plans
with it) and queries no database table. Entries are JSON by robot id in hashes under coordination.key("traffic",
name); an entry with "expires" in the past is no longer read (a dead worker's lapses).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import math
import time

from redis.exceptions import WatchError

import live
from execution import coordination
from execution.steps import StepFailed
from fleetcore import traffic as plain
from fleetcore import traffic_tuning as tune
from robots import poses as pose_store
from robots.models import Robot

log = logging.getLogger(__name__)


def key(name: str) -> str:
    return coordination.key("traffic", name)


def read(redis, name: str) -> dict[int, dict]:
    """A traffic hash's entries by robot id, without the lapsed ones."""
    return _live(redis.hgetall(key(name)))


def read_all(redis, *names: str) -> list[dict[int, dict]]:
    """Several traffic hashes (read), in one round trip."""
    with redis.pipeline(transaction=False) as pipe:
        for name in names:
            pipe.hgetall(key(name))
        return [_live(raw) for raw in pipe.execute()]


def _live(raw_entries: dict) -> dict[int, dict]:
    now, out = time.time(), {}
    for field, raw in raw_entries.items():
        entry = json.loads(raw)
        if entry.get("expires", math.inf) > now:
            out[int(field)] = entry
    return out


def write(redis, name: str, robot_id: int, entry: dict) -> None:
    redis.hset(key(name), str(robot_id), json.dumps(entry, separators=(",", ":")))


# The turn goes to the first live waiter in the queue (lowest score): waiters whose liveness key lapsed (their
# executor died) are dropped from its head; taken, the turn is a key of its own, as before.
TAKE_TURN = """
while true do
  local head = redis.call('zrange', KEYS[2], 0, 0)[1]
  if not head or redis.call('exists', KEYS[3] .. head) == 1 then break end
  redis.call('zrem', KEYS[2], head)
end
if redis.call('zrange', KEYS[2], 0, 0)[1] == ARGV[1]
   and redis.call('set', KEYS[1], ARGV[1], 'NX', 'PX', ARGV[2]) then
  redis.call('zrem', KEYS[2], ARGV[1])
  return 1
end
return 0
"""


@contextlib.asynccontextmanager
async def planning_turn(robot: Robot, progress=None, longest: float = 0.0):
    """One plan at a time across the fleet (prioritized planning: robots sent together are planned in turn,
    each against the paths reserved before it, instead of all against the same snapshot), the longest trips
    first (`longest`: the seconds this one is expected to take): the robots that decide when the fleet is
    done get the ways the others then go round, and the ones planned last are those with time to spare. A
    turn that does not come within TURN_WAIT_S is not waited for (the claims still keep robots apart); a
    planner that dies lets its turn lapse after TURN_TTL_MS, a waiter that dies leaves the queue after
    TURN_WAITER_TTL_MS. Waited for on the loop: a robot waiting for its turn holds no thread of the executor's
    blocking pool (32 robots sent together, 8 to a pool of 8, held them all polling)."""
    redis, token = coordination.aconnection(), coordination.new_token()
    queue, waiters = key("turn:queue"), key("turn:waiter:")
    alive = waiters + token
    deadline = time.monotonic() + tune.TURN_WAIT_S
    held = False
    try:
        while True:
            async with redis.pipeline(transaction=False) as pipe:
                # alive before queued (never queued and lapsed), and queued again each time (a waiter whose loop
                # was late by TURN_WAITER_TTL_MS was dropped)
                pipe.set(alive, 1, px=tune.TURN_WAITER_TTL_MS)
                pipe.zadd(queue, {token: -longest}, nx=True)
                pipe.eval(TAKE_TURN, 3, key("turn"), queue, waiters, token, tune.TURN_TTL_MS)
                held = bool((await pipe.execute())[2])
            if held:
                break
            if time.monotonic() > deadline:
                log.info("traffic: %s plans without waiting longer for its turn", robot.name)
                break
            if progress is not None:
                progress()
            await asyncio.sleep(tune.TURN_POLL_S)
    finally:
        if not held:  # (gave up, stopped or cancelled: out of the queue)
            await asyncio.shield(_leave_queue(redis, queue, alive, token))
    try:
        yield
    finally:
        if held:  # (cancelled, the turn lapses after TURN_TTL_MS instead)
            await asyncio.shield(redis.eval(coordination.RELEASE, 1, key("turn"), token))


async def _leave_queue(redis, queue: str, alive: str, token: str) -> None:
    async with redis.pipeline(transaction=False) as pipe:
        pipe.zrem(queue, token)
        pipe.delete(alive)
        await pipe.execute()


def request_way(redis, robot: Robot, radius: float, idle: dict, through) -> None:
    """Ask, in the traffic table, the idle robots in the way to make way for this robot (of that radius): sent
    after the turn (execution.traffic.ask_to_make_way), read by their make_way step (way_request)."""
    points = [[round(p[0], 2), round(p[1], 2)] for p in through]
    for pk in idle:
        entry = {"for": robot.pk, "r": radius, "route": points, "sent": False}
        write(redis, "makeway", pk, {**entry, "expires": time.time() + tune.MAKE_WAY_TTL_S})
    log.info("traffic: %s asks %s to make way", robot.name, sorted(idle))


def waiting_for(redis, robot_id: int) -> list[int]:
    """The robots waiting for this one (their waits entry names it)."""
    return [pk for pk, wait in read(redis, "waits").items() if wait.get("for") == robot_id]


def way_request(robot: Robot) -> dict | None:
    """What the robot is to make way for: {"for": id, "r": its reach, "route": [[x, y], ...]}; asked by a plan
    (request_way), or, for a person who told it to, the first robot waiting for it (along its reserved
    path). None when nobody needs its room."""
    redis = coordination.connection()
    entry = read(redis, "makeway").get(robot.pk)
    if entry is not None and not entry.get("done") and not entry.get("refused"):
        return entry
    plans = read(redis, "plans")
    for pk in waiting_for(redis, robot.pk):
        if pk in plans:
            return {"for": pk, "r": plans[pk]["r"], "route": plans[pk]["path"]}
    return None


def made_way(robot: Robot, failed: str = "") -> None:
    """The robot is back: its request is done, and stays so until it lapses (the robot that asked does not ask
    it again on a later plan of its trip; another robot may). Or it could not make way: the request stays,
    refused (the robot that asked goes round it; nobody asks it again for a while)."""
    redis = coordination.connection()
    entry = read(redis, "makeway").get(robot.pk)
    if entry is None:
        return
    outcome = {"refused": failed} if failed else {"done": True}
    write(redis, "makeway", robot.pk, {**entry, "sent": True, "refused": "", **outcome})


def reserve(redis, robot: Robot, path: list[tuple], radius: float, now: float, heeds: float) -> None:
    """Write the robot's plan: its reserved cells (for the plans after it), its timed path up to where it
    heeded the others' reservations (`heeds` s ahead: the claims keep its order there, first_to_pass), and its
    route for the map."""
    table = plain.ReservationTable()
    table.reserve_path(str(robot.pk), path, radius + tune.SPACING_M, plain.pad(now))
    busy = table.intervals()  # merged per cell: a few intervals each, not one per stretch that touches it
    cells = [
        [c, r, round(t0, 2), round(t1, 2)]
        for (c, r), spans in busy.cells.items()
        for t0, t1 in zip(spans.starts, spans.ends, strict=True)
    ]
    x, y, at = path[-1]
    entry = {"cells": cells, "goal": [x, y], "r": radius, "at": at, "expires": at + tune.WAIT_LIMIT_S * 2}
    entry["path"] = [[round(p[0], 2), round(p[1], 2)] for p in path[:: max(1, len(path) // tune.MAP_POINTS)]]
    entry["path"].append([round(x, 2), round(y, 2)])  # what a map that opens now draws (routes())
    timed = [[round(x, 3), round(y, 3), round(t, 2)] for x, y, t in path]  # its order, for the claims
    with redis.pipeline() as pipe:  # (one transaction: a claim never reads one plan's cells, another's order)
        write(pipe, "plans", robot.pk, entry)
        order = {
            "path": timed,
            "r": radius,
            "until": round(now + min(heeds, 1e6), 2),
            "expires": entry["expires"],
        }
        write(pipe, "timed", robot.pk, order)
        pipe.execute()


def routes(robot_ids) -> dict[int, dict]:
    """{robot id: {"path": [[x, y], ...], "waiting_for": robot id or None}} of the robots under traffic now,
    for a page that opens while they drive (live.path sends the changes after)."""
    redis, wanted = coordination.connection(), set(robot_ids)
    waits = {pk: entry.get("for") for pk, entry in read(redis, "waits").items() if pk in wanted}
    plans = {pk: entry.get("path", []) for pk, entry in read(redis, "plans").items() if pk in wanted}
    return {
        pk: {"path": plans.get(pk, []), "waiting_for": waits.get(pk)} for pk in plans.keys() | waits.keys()
    }


def try_claim(redis, robot: Robot, start, end, radius: float, everyone, planned, why, progress) -> int | None:
    """Check and write a claim in one transaction (WATCH on the claims: optimistic, no lock to wait for or to
    lapse): the id of the robot in the way, or None when the claim is written (execution.traffic.claim says
    what the arguments are). Claims lost to others' writes are tried again, for CLAIM_LIMIT_S at most."""
    deadline = time.monotonic() + tune.CLAIM_LIMIT_S
    while True:
        with redis.pipeline() as pipe:
            try:
                pipe.watch(key("claims"))
                return _claim(pipe, robot, start, end, radius, everyone, planned, why)
            except WatchError:  # another robot's claim was written between our read and our write: again
                if time.monotonic() > deadline:
                    raise StepFailed("the traffic table is too busy to claim a stretch; try again") from None
                if progress is not None:
                    progress()


def _claim(pipe, robot: Robot, start, end, radius: float, everyone, planned, why) -> int | None:
    """Within a WATCH on the claims: the robot in the way, or write the claim (and drop the robot's wait)."""
    held = {pk: e for pk, e in _live(pipe.hgetall(key("claims"))).items() if pk != robot.pk}
    claims = {pk: plain.entry_capsule(pk, e) for pk, e in held.items()}
    others = [*claims.values(), *(disc for disc, _ in everyone if int(disc.label) not in claims)]
    blocker = plain.first_in_the_way(
        tuple(start), tuple(end), radius, others, tune.CLAIM_MARGIN, tune.APPROACH_SLACK
    )
    if blocker is None and planned is not None and tuple(start) != tuple(end):
        others = _planned(pipe, held)
        blocker = plain.first_to_pass(tuple(start), tuple(end), *planned, radius, others, tune.ORDER_ZONE)
    if blocker is not None:
        pipe.unwatch()
        if why is not None:
            why.append("room" if isinstance(blocker, plain.Capsule) else "order")
        return int(blocker.label if isinstance(blocker, plain.Capsule) else blocker)
    entry = {"a": list(start), "b": list(end), "r": radius, "expires": time.time() + tune.CLAIM_TTL_S}
    if planned is not None:
        entry["t"] = planned[0]
    pipe.multi()
    pipe.hset(key("claims"), str(robot.pk), json.dumps(entry, separators=(",", ":")))
    pipe.hdel(key("waits"), str(robot.pk))
    pipe.execute()
    return None


def _planned(redis, held: dict[int, dict]) -> list[plain.Planned]:
    """The timed plans of the other robots under way (holding a claim: a plan whose robot's worker died
    lapses with its claim) that heeded the reservations, each with its progress (the planned time of the
    stretch it holds; its plan's start until it claims one) and the time up to which it heeded them."""
    out = []
    for pk, entry in read(redis, "timed").items():
        if pk in held and entry["until"] > entry["path"][0][2]:
            path = [tuple(p) for p in entry["path"]]
            progress = held[pk].get("t", path[0][2])
            out.append(plain.Planned(str(pk), path, entry["r"], progress, entry["until"]))
    return out


def drop_plan(robot: Robot) -> None:
    """The robot has no plan now (none found): it stands, and the others plan round it and wait for nothing of
    its old way."""
    redis = coordination.connection()
    with redis.pipeline() as pipe:
        for name in ("plans", "timed"):
            pipe.hdel(key(name), str(robot.pk))
        pipe.execute()


def release(robot: Robot, pose) -> None:
    """The step has ended: drop the robot's reservation, claim and wait; remember where it parked."""
    redis = coordination.connection()
    with redis.pipeline() as pipe:
        for name in ("plans", "timed", "claims", "waits", "breaks"):
            pipe.hdel(key(name), str(robot.pk))
        if pose is not None:
            pipe.hset(key("parked"), str(robot.pk), json.dumps({"x": pose[0], "y": pose[1]}))
        pipe.execute()
    if pose is not None:
        pose_store.store_pose(robot.pk, pose)
    live.path(robot, [], None)


def deadlocks() -> int:
    """Wait-for cycles found and broken so far (the bench reads it)."""
    return int(coordination.connection().get(key("deadlocks")) or 0)


def renew(redis, robot_id: int) -> None:
    """Keep the robot's claim (where it stands and what it holds) alive while it waits, once it is needed
    (each write of the claims makes the others' claims in flight try again)."""
    raw = redis.hget(key("claims"), str(robot_id))
    if raw is None:
        return
    entry = json.loads(raw)
    if entry.get("expires", 0) - time.time() < tune.RENEW_BEFORE_S:
        write(redis, "claims", robot_id, {**entry, "expires": time.time() + tune.CLAIM_TTL_S})


def known_pace(robot_id: int) -> float | None:
    """The pace a robot's nav stack was seen to keep (m per second of the robot's clock), None if never seen."""
    raw = coordination.connection().hget(key("pace"), str(robot_id))
    return float(raw) if raw else None


def break_deadlock(redis, robot_id: int) -> tuple[list[str], dict, dict] | None:
    """If this robot is in a cycle of waits and is the one to give way, count it (the deadlock, the robot's
    breaks) and drop its wait: (the cycle's ids, the room each holds, what each waits for); else None. The one
    to give way has given way least often on its trip, ties to the highest id: a robot whose reroutes did not
    get it out of the others' way is not asked again and again while they wait.

    Read and decided under a WATCH of the waits, and the breaker's wait dropped in the same transaction: two
    robots of one cycle checking at once both broke it (run r: the second read the first's count of breaks
    but still its wait), each backing off and counted as a deadlock."""
    with redis.pipeline() as pipe:
        try:
            pipe.watch(key("waits"))
            entries = read(pipe, "waits")
            waits = {str(pk): str(entry["for"]) for pk, entry in entries.items()}
            cycle = plain.wait_cycle(waits, str(robot_id))
            if not cycle:
                return None
            given = dict(zip(cycle, pipe.hmget(key("breaks"), cycle), strict=True))
            if min(cycle, key=lambda pk: (int(given[pk] or 0), -int(pk))) != str(robot_id):
                return None
            held = {pk: (e["a"], e["b"]) for pk, e in read(pipe, "claims").items() if str(pk) in cycle}
            pipe.multi()
            pipe.hdel(key("waits"), str(robot_id))
            pipe.incr(key("deadlocks"))
            pipe.hincrby(key("breaks"), str(robot_id), 1)
            pipe.execute()
        except WatchError:  # a wait changed as we read: the next check (NOTE_WAIT_S on) reads it afresh
            return None
    why = {  # what each waits for (room, or its turn: order) and the stretch it waits to drive
        pk: (entries[int(pk)].get("why"), entries[int(pk)].get("to")) for pk in cycle
    }
    return cycle, held, why


def note_pace(robot_id: int, seen: float) -> None:
    """Learn a nav stack's pace (m per second of the robot's clock) from one measure of it, weighed against
    what was known (PACE_WEIGHT): later plans are timed by it."""
    known = known_pace(robot_id)
    pace = seen if known is None else tune.PACE_WEIGHT * seen + (1 - tune.PACE_WEIGHT) * known
    coordination.connection().hset(key("pace"), str(robot_id), f"{pace:.4f}")
