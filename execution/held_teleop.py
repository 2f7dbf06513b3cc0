"""Teleop over one page's WebSocket: the checks once per press, then every repeat straight from the event loop.

A held button sends its command every 0.2 s, and a fleet page may hold many robots' buttons at once. So:

- The first command for a robot runs the checks in a thread (role, lease, running instruction, move topic:
  control.teleop_grants), the first commands of robots pressed together in one call; a refusal is answered
  in words and audited.
- Under the grant this gives, commands are published with one send on this loop's own rosbridge link: no
  thread, no database, and no task of its own when the link is idle. A robot's commands go out in the order
  they came; different robots' never wait for each other.
- A grant is dropped when the robot's lease or state changes (the pushes every page gets: drop()), and all
  grants in use are re-checked at once, in one thread call, every GRANT_S / 2; a grant not used since the
  last re-check is dropped (the button was released). A refusal found then is said to the person.
- A change of speed is audited after it was published, from a thread, changes that come while one write is
  under way going together in the next; a repeat is not audited.
- Each press is answered (command.result), but after the publishes: the answers of presses read together go
  to the page once the socket has nothing more to read, as one {"type": "batch"} frame when there are several
  (the page reads batches: static/fleet/live.js). Answering each press before reading the next one had the
  next robot's command wait behind an answer's encoding, compression and write (bench.run --only latency: with
  100 robots pressed at once the portal took twice a bare relay's time per frame).
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Awaitable, Callable

from channels.db import database_sync_to_async
from django.utils import timezone

import live

log = logging.getLogger(__name__)

GATHER_S = 0.002  # presses arriving within this share one check (a check takes a few ms itself)


class HeldTeleop:
    """One socket's teleop: grants per robot, per-robot ordered publishing, re-checks and write-behind audit."""

    def __init__(
        self, user, send_json: Callable[[dict], Awaitable[None]], checks, control, stops: set | None = None
    ) -> None:
        self.user, self.send_json = user, send_json
        self.checks = checks  # (user, robot ids) -> {id: grant, or the refusal}, in a thread
        self.control = control  # execution.control: teleop_grants, publish_teleop, audit_teleops, GRANT_S
        self.grants: dict[int, object] = {}
        self.used: set[int] = set()
        self.audited: dict[int, tuple[float, float]] = {}
        self.chains: dict[object, asyncio.Future] = {}
        self.unaudited: list[tuple] = []
        self.auditing: asyncio.Task | None = None
        self.answers: list[dict] = []  # answers not yet sent, in the order of their presses
        self.answering: asyncio.Task | None = None
        self.rechecking: asyncio.Task | None = None
        self.wanted: dict[int, asyncio.Future] = {}  # presses waiting for their checks
        self.checking: asyncio.Task | None = None
        # this page's stops whose bookkeeping is under way: the page socket's own set, so that its stops from
        # before its first teleop press count too
        self.stops: set[asyncio.Task] = set() if stops is None else stops
        self.stop_count = 0  # stops seen; with the count at each robot's (or "all"'s) last one
        self.last_stop: dict[object, int] = {}

    async def take(self, content: dict, linear: float, angular: float) -> None:
        """One command: published from here (no task: one turn of the loop less on its way) under a valid grant
        when none of the robot's is under way and its link takes it at once; else queued behind the same robot's
        earlier ones (and no one else's). Never awaited here: checks, a link connecting or backed up; the page's
        next frame (a STOP) must not wait behind one robot's command."""
        key = content.get("robot")
        key = key if isinstance(key, int) else repr(key)
        grant = self.grants.get(content.get("robot"))
        if (
            key not in self.chains
            and grant is not None
            and grant.valid
            and self.control.link_idle(grant.endpoint)
        ):
            await self._publish(grant, content, linear, angular)
            return
        task = asyncio.ensure_future(
            self._one(self.chains.get(key), content, linear, angular, self.stop_count)
        )
        self.chains[key] = task
        task.add_done_callback(lambda done: self.chains.get(key) is done and self.chains.pop(key))

    def drop(self, robot_id) -> None:
        """The robot's lease or state changed: its next command goes through the checks again."""
        self.grants.pop(robot_id, None)

    def stopped(self, robot_ids, bookkeeping: asyncio.Task) -> None:
        """The page stopped these robots ("all": every one), its bookkeeping (control.stop) under way. Their grants
        go at once; a command the page sent before the STOP and not out yet is not sent after the zero; one sent
        after it is checked once the bookkeeping is done (a person may still drive a robot a stop holds:
        access.holds)."""
        for robot_id in list(self.grants) if robot_ids == "all" else robot_ids:
            self.drop(robot_id)
        self.stop_count += 1
        for key in ["all"] if robot_ids == "all" else robot_ids:
            self.last_stop[key] = self.stop_count
        self.stops.add(bookkeeping)
        bookkeeping.add_done_callback(self.stops.discard)

    def close(self) -> None:
        for task in [*self.chains.values(), self.rechecking, self.answering]:
            if task is not None:
                task.cancel()  # the socket that wanted these repeats (and their answers) is gone

    async def _one(self, previous, content: dict, linear: float, angular: float, stops_seen: int) -> None:
        """One queued command (stops_seen: how many of the page's stops were read before it)."""
        if previous is not None:
            await asyncio.gather(previous, return_exceptions=True)
        grant = self.grants.get(content.get("robot"))
        checked = grant is None or not grant.valid
        if checked:
            if self.stops:  # a STOP before this press: its bookkeeping first, so the checks see what it did
                await asyncio.gather(*list(self.stops), return_exceptions=True)
            try:
                grant = await self._check(content.get("robot"))
            except Exception as exc:  # refused (the checks audited it), or no such robot: said in words
                self._answer({**_reply(content), "ok": False, "detail": str(exc) or type(exc).__name__})
                return
        if max(self.last_stop.get(grant.robot_id, 0), self.last_stop.get("all", 0)) > stops_seen:
            # the page's STOP was read after this command: it is not sent after the zero (nor its grant kept)
            detail = f"{grant.robot_name}: stopped after this command was sent; not sent"
            self._answer({**_reply(content), "ok": False, "detail": detail})
            return
        if checked:
            self.grants[grant.robot_id] = grant
            if self.rechecking is None or self.rechecking.done():
                self.rechecking = asyncio.ensure_future(self._recheck())
        await self._publish(grant, content, linear, angular)

    async def _publish(self, grant, content: dict, linear: float, angular: float) -> None:
        """Publish under the grant, then audit a change and answer the press."""
        reply = _reply(content)
        try:
            v, w = await self.control.publish_teleop(grant, linear, angular)
        except Exception as exc:  # the link went down under the grant: said in words, grant dropped
            self.drop(grant.robot_id)
            self._answer({**reply, "ok": False, "detail": str(exc) or type(exc).__name__})
            return
        self.used.add(grant.robot_id)
        if self.audited.get(grant.robot_id) != (v, w):
            self.audited[grant.robot_id] = (v, w)
            self._audit(grant.robot_name, v, w)
        detail = f"{grant.robot_name}: linear {v:.2f} m/s, angular {w:.2f} rad/s"
        self._answer({**reply, "ok": True, "detail": detail})

    def _answer(self, reply: dict) -> None:
        """Say a press's outcome on the page's socket, once this loop turns (see the module's docstring)."""
        self.answers.append(reply)
        if self.answering is None or self.answering.done():
            self.answering = asyncio.ensure_future(self._send_answers())

    async def _send_answers(self) -> None:
        """The answers gathered so far, in one frame; a socket closed meanwhile (the page went away while its
        presses were under way: uvicorn's ClientDisconnected is an OSError) is no error, the commands went out."""
        while self.answers:
            batch, self.answers = self.answers, []
            try:
                await self.send_json(live.page_frame(batch))
            except OSError as exc:
                log.debug("teleop: the page went away before %d answers: %r", len(batch), exc)
                return

    async def _check(self, robot_id):
        """A press's checks; presses that come together (a whole fleet's) are checked in one thread call."""
        if not isinstance(robot_id, int) or isinstance(robot_id, bool):
            raise LookupError("robot: no such robot")
        wanted = self.wanted.get(robot_id)
        if wanted is None:
            wanted = self.wanted[robot_id] = asyncio.get_running_loop().create_future()
            if self.checking is None or self.checking.done():
                self.checking = asyncio.ensure_future(self._check_wanted())
        return await wanted

    async def _check_wanted(self) -> None:
        check = database_sync_to_async(self.checks, thread_sensitive=False)
        await asyncio.sleep(GATHER_S)  # the other presses of a burst, read from the socket meanwhile
        while self.wanted:
            batch, self.wanted = self.wanted, {}
            try:
                found = await check(self.user, list(batch))
            except Exception as exc:  # the database is away: every press waiting is told why
                found = dict.fromkeys(batch, exc)
            for robot_id, wanted in batch.items():
                if not wanted.done():
                    grant = found[robot_id]
                    wanted.set_exception(grant) if isinstance(grant, Exception) else wanted.set_result(grant)

    async def _recheck(self) -> None:
        """Renew the grants in use with one batched check; drop the unused and the refused ones."""
        check = database_sync_to_async(self.control.teleop_grants, thread_sensitive=False)
        while self.grants:
            await asyncio.sleep(self.control.GRANT_S / 2)
            used, self.used = self.used, set()
            for robot_id in set(self.grants) - used:  # released: the next press is checked and audited anew
                self.grants.pop(robot_id, None)
                self.audited.pop(robot_id, None)
            if not self.grants:
                break
            try:
                fresh = await check(list(self.grants), self.user)
            except Exception:  # the database is away: the grants run out, and commands go the full way
                log.exception("teleop re-check failed")
                continue
            for robot_id, grant in fresh.items():
                if robot_id not in self.grants:
                    continue  # dropped (a lease or state push) while the check ran
                if isinstance(grant, Exception):
                    self.grants.pop(robot_id, None)
                    reply = {"type": "command.result", "command": "teleop", "ref": None, "ok": False}
                    self._answer({**reply, "detail": str(grant)})
                else:
                    self.grants[robot_id] = grant

    def _audit(self, robot_name: str, v: float, w: float) -> None:
        """Write-behind: changes wait while one write is under way, then go together in the next."""
        self.unaudited.append((robot_name, timezone.now(), v, w))
        if self.auditing is None or self.auditing.done():
            self.auditing = asyncio.ensure_future(self._write_audit())

    async def _write_audit(self) -> None:
        write = database_sync_to_async(self.control.audit_teleops, thread_sensitive=False)
        while self.unaudited:
            batch, self.unaudited = self.unaudited, []
            try:
                await write(self.user, batch)
            except Exception:  # the trail must not stop the robots; the log keeps what was lost
                log.exception("teleop audit of %d changes failed: %s", len(batch), batch)


def _reply(content: dict) -> dict:
    return {"type": "command.result", "command": "teleop", "ref": content.get("ref")}
