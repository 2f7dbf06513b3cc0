"""Register rosbridge endpoints: check, discover, identify, store robots and their graph, record what changed.

A batch never fails as a whole. Each URL asked for gets its own RegistrationRecord, created before anything
connects (the API hands their ids back, so a background registration is always queryable) and always
finished: registered, or refused with a one-line reason. Before connecting, each URL is parsed, resolved and
checked against the allowed networks (robots.endpoints); aliases of one endpoint are discovered once.
Endpoints are discovered concurrently (one asyncio loop, one connection each, ENDPOINTS_AT_ONCE at a time so
that the frame limit bounds memory); each endpoint's result is stored in its own transaction. Robots are
untrusted input: whatever one endpoint answers (nonsense, garbage, oversize) costs that endpoint alone.

Errors never tell which ports are open: whatever fails before a rosbridge server has answered once
(refused, no route, silent, HTTP, garbage) reads "unreachable (no rosbridge server answered)"; the precise
reason goes to the log. Re-registration updates rows in place, keyed by (endpoint, namespace); a person's
binding choice survives while its target still exists.
"""

from __future__ import annotations

import asyncio
import logging
import re
from collections.abc import Callable
from dataclasses import dataclass, field

from django.conf import settings
from django.db import transaction
from django.utils import timezone

import live
from audit import records as audit
from robots import endpoints, identify, kinematics
from robots.discovery import BadReply, Graph, discover
from robots.models import Binding, Node, Param, RegistrationRecord, Robot, Service, Topic, robot_name_from
from robots.rosbridge import FrameTooLarge, RosbridgeClient, RosbridgeError
from robots.signals import robots_registered

log = logging.getLogger("robots.registration")
ENDPOINT_TIMEOUT = 15.0  # a whole endpoint's discovery, beyond the per-call timeouts
ENDPOINTS_AT_ONCE = 4  # endpoints discovered concurrently: memory is at most this many frame limits' worth
LIST_LIMIT = 50  # names kept per change list in RegistrationRecord.changes
URL_SHOWN = 255  # characters of a URL kept in a record (the column's size)
UNREACHABLE = "unreachable (no rosbridge server answered)"


@dataclass
class EndpointResult:
    url: str  # as asked for
    ok: bool = False
    error: str = ""
    robots: list[str] = field(default_factory=list)
    changes: dict = field(default_factory=dict)
    record_id: int | None = None
    endpoint: str = ""  # the canonical URL stored on the robots ("" when refused before resolution)


# ----- discovery (async, no database) -----
def endpoint_timeout() -> float:
    """Seconds a whole endpoint's discovery may take: FLEET_DISCOVERY_TIMEOUT_S, else ENDPOINT_TIMEOUT."""
    return float(getattr(settings, "FLEET_DISCOVERY_TIMEOUT_S", ENDPOINT_TIMEOUT))


async def discover_one(url: str, call_timeout: float = 3.0) -> list[Graph] | RosbridgeError:
    """Discover one endpoint; every failure comes back as a RosbridgeError with a one-line reason, never raised."""
    client = RosbridgeClient(url, call_timeout=call_timeout)
    try:
        await client.connect()
        return await asyncio.wait_for(discover(url, client), endpoint_timeout())
    except (BadReply, FrameTooLarge) as exc:
        return exc
    except RosbridgeError as exc:
        if not client.answered:  # nothing that speaks rosbridge: say so without telling what is there
            log.info("%s", exc)
            return RosbridgeError(f"{url}: {UNREACHABLE}")
        return exc
    except TimeoutError:
        return RosbridgeError(f"{url}: discovery took longer than {endpoint_timeout():g} s")
    except Exception as exc:  # a reply we did not foresee: that endpoint fails, the batch goes on
        log.exception("%s: discovery failed", url)
        return RosbridgeError(f"{url}: refused: discovery failed on what it answered ({type(exc).__name__})")
    finally:
        await client.close()


async def discover_all(
    urls: list[str], call_timeout: float = 3.0, allowed: endpoints.AllowList | None = None
) -> list[tuple[str, list[Graph] | RosbridgeError]]:
    """(canonical URL or "", graphs or error) per URL; aliases of one endpoint are discovered once."""
    allowed = allowed or endpoints.allow_list()
    resolved = await asyncio.gather(*(endpoints.resolve(u, allowed) for u in urls), return_exceptions=True)
    unique = list(dict.fromkeys(r for r in resolved if isinstance(r, str)))
    gate = asyncio.Semaphore(ENDPOINTS_AT_ONCE)

    async def one(url: str):
        async with gate:
            return await discover_one(url, call_timeout)

    found = dict(zip(unique, await asyncio.gather(*(one(u) for u in unique)), strict=True))
    return [
        (r, found[r]) if isinstance(r, str) else ("", _as_error(url, r))
        for url, r in zip(urls, resolved, strict=True)
    ]


def _as_error(url: str, exc: BaseException) -> RosbridgeError:
    if isinstance(exc, RosbridgeError):
        return exc
    log.error("%s: could not check the URL", url, exc_info=exc)
    return RosbridgeError(f"{url[:URL_SHOWN]}: refused: not a URL the portal can check")


# ----- the entry point -----
def clean_urls(urls) -> list[str]:
    """The URLs asked for, stripped, blanks and exact repeats left out, in order."""
    return list(dict.fromkeys(u.strip() for u in urls if isinstance(u, str) and u.strip()))


def begin(urls: list[str], user=None) -> list[RegistrationRecord]:
    """One record per URL, unfinished: what a background registration hands back before it starts."""
    owner = user if _real(user) else None
    return [RegistrationRecord.objects.create(endpoint=u[:URL_SHOWN], user=owner) for u in urls]


def register_endpoints(
    urls: list[str], user=None, call_timeout: float = 3.0, record_ids: list[int] | None = None
) -> list[EndpointResult]:
    """Register every endpoint (concurrently); return one result per URL, in order. Never raises for a URL."""
    urls = clean_urls(urls)
    records = _records(urls, user, record_ids)
    try:
        found = asyncio.run(discover_all(urls, call_timeout))
        return store_all(urls, found, user, records)
    finally:
        abandon([r for r in records if r is not None])


def _records(urls: list[str], user, record_ids: list[int] | None) -> list[RegistrationRecord | None]:
    if record_ids is None:
        return list(begin(urls, user))
    by_id = RegistrationRecord.objects.in_bulk(record_ids)
    return [by_id.get(pk) for pk in record_ids] + [None] * (len(urls) - len(record_ids))


def abandon(records: list[RegistrationRecord], reason: str = "registration stopped unexpectedly") -> None:
    """Finish, as failed, records a registration left unfinished (it stopped on an error of its own)."""
    unfinished = RegistrationRecord.objects.filter(pk__in=[r.pk for r in records], finished_at=None)
    unfinished.update(finished_at=timezone.now(), ok=False, error=reason)


def store_all(urls: list[str], found: list, user=None, records=None) -> list[EndpointResult]:
    """Store discovered graphs (or errors), one result per URL, and attach the current world's schedules."""
    vocab = load_vocabulary()
    records = records or [None] * len(urls)
    done: dict[str, EndpointResult] = {}
    results = []
    for url, (endpoint, graphs), record in zip(urls, found, records, strict=True):
        first = done.get(endpoint) if endpoint else None
        if first is not None:  # an alias of an endpoint already registered in this batch
            result = EndpointResult(url, first.ok, first.error, list(first.robots), {}, None, endpoint)
        else:
            result = store_endpoint(url, graphs, vocab, user, endpoint=endpoint)
            done[endpoint] = result
        results.append(finish(result, record, user))
    registered = [robot for result in results if result.ok for robot in result.robots]
    if registered:
        robots_registered.send(sender=Robot, robots=registered)
    return results


def store_endpoint(
    url: str, graphs, vocab: identify.Vocabulary, user=None, endpoint: str = ""
) -> EndpointResult:
    """Store one endpoint's robots in one transaction; whatever goes wrong becomes that endpoint's error."""
    endpoint = endpoint or url
    result = EndpointResult(url, endpoint=endpoint if not isinstance(graphs, BaseException) else "")
    if isinstance(graphs, BaseException):
        result.error = str(graphs) or type(graphs).__name__
        return result
    try:
        with transaction.atomic():
            batch = Batch.of(endpoint)
            for graph in graphs:
                robot, changes = store_robot(endpoint, graph, vocab, batch)
                result.robots.append(robot.name)
                if changes:
                    result.changes[robot.name] = changes
            batch.insert()
            missing = mark_missing(endpoint, {g.namespace for g in graphs})
            if missing:
                result.changes["missing_robots"] = missing
        result.ok = True
    except Exception as exc:  # e.g. a name the database refuses: that endpoint fails, the batch goes on
        log.exception("%s: could not store its robots", endpoint)
        result.robots, result.changes = [], {}
        result.error = f"{url}: refused: could not store what it answered ({type(exc).__name__})"
    return result


def finish(result: EndpointResult, record: RegistrationRecord | None, user=None) -> EndpointResult:
    """Write the result into its record (created now when none was begun), push it and audit it."""
    record = record or RegistrationRecord(endpoint=result.url[:URL_SHOWN], user=user if _real(user) else None)
    record.endpoint = (result.endpoint or result.url)[:URL_SHOWN]
    record.ok, record.error, record.robots, record.changes = (
        result.ok,
        result.error,
        result.robots,
        result.changes,
    )
    record.finished_at = timezone.now()
    record.save()
    result.record_id = record.pk
    try:  # stored first: a push that fails (Redis away) loses nothing
        live.registration(
            record.endpoint, "done" if result.ok else "failed", result.error, result.robots, ok=result.ok
        )
    except Exception:
        log.warning("%s: could not push the registration's outcome", record.endpoint, exc_info=True)
    audit.record(user, "register", record.endpoint, ok=result.ok, robots=result.robots, error=result.error)
    return result


def _real(user) -> bool:
    return getattr(user, "is_authenticated", False)


# ----- one endpoint's robots, read and written together -----
@dataclass
class Batch:
    """What storing one endpoint's robots reads once and writes together, in its transaction.

    Its robots and the names taken are read in two queries, not two per robot; the rows of new robots (topics,
    nodes, services, params, bindings) are inserted with one bulk insert per kind for the whole endpoint
    (insert()), not one per kind per robot. Each robot is still saved on its own (its post_save bumps the
    fleet's version; a unique name is checked by the database). A 250-robot endpoint took 3.9 s to store with
    a round trip per robot and kind (docs/scale.md, "Registration")."""

    known: dict[str, Robot]  # namespace -> the endpoint's robot already registered
    taken: set[str]  # every robot's name
    new_rows: dict[type, list] = field(default_factory=dict)  # model -> rows of new robots, to insert

    @classmethod
    def of(cls, endpoint: str) -> Batch:
        return cls(
            known={robot.namespace: robot for robot in Robot.objects.filter(endpoint=endpoint)},
            taken=set(Robot.objects.values_list("name", flat=True)),
        )

    def add(self, model, rows: list) -> None:
        self.new_rows.setdefault(model, []).extend(rows)

    def insert(self) -> None:
        for model, rows in self.new_rows.items():
            model.objects.bulk_create(rows, batch_size=INSERT_BATCH)
        self.new_rows = {}


INSERT_BATCH = 2000  # rows per INSERT: well under PostgreSQL's 65,535 parameters for the widest row


# ----- one robot -----
def store_robot(url: str, graph: Graph, vocab: identify.Vocabulary, batch: Batch) -> tuple[Robot, dict]:
    """Create or update one robot and its graph; return it with the changes. A new robot's rows wait in the
    endpoint's batch (store_endpoint inserts them: batch.insert())."""
    robot = batch.known.get(graph.namespace)
    changes: dict = {}
    model = kinematics.guess_model(graph)
    if robot is None:
        robot = Robot(
            endpoint=url, namespace=graph.namespace, name=unique_name(graph.name, model, batch.taken)
        )
        changes["created"] = True
    max_linear, max_angular, limits_source = kinematics.limits(graph, model)
    facts = graph.urdf
    robot.model = model
    robot.drive = facts.drive if facts else Robot.Drive.OTHER
    robot.wheel_count = facts.wheel_count if facts else None
    robot.leg_count = facts.leg_count if facts and facts.leg_count else None
    robot.footprint = facts.footprint if facts else []
    robot.max_linear, robot.max_angular = max_linear, max_angular
    robot.ros_version = graph.ros_version
    robot.start_pose = graph.start_pose or robot.start_pose or [0.0, 0.0, 0.0]
    robot.description = {
        **(facts.as_dict() if facts else {}),
        "urdf_error": graph.urdf_error,
        "limits_source": limits_source,
        "start_pose_source": graph.start_pose_source or "default (0, 0, 0)",
    }
    robot.link_status, robot.last_seen = Robot.Link.ONLINE, timezone.now()
    robot.save()
    if "created" in changes:  # a new robot has no rows yet: nothing to look up, its rows go with the batch's
        batch.taken.add(robot.name)
        batch.known[robot.namespace] = robot
        sync_graph(robot, graph, new_rows=batch)
        sync_bindings(robot, graph, vocab, new_rows=batch)
        return robot, changes
    # re-registration: only what changed is recorded
    changes.update(sync_graph(robot, graph), **sync_bindings(robot, graph, vocab))
    return robot, changes


def unique_name(name: str, model: str = "", taken: set[str] | None = None) -> str:
    """The robot's name, else its model's (or "robot"), then `_2`, `_3`... if taken: never a host or port.

    Names are words of the instructions people type ("move turtlebot3_burger_2 to A"), so they hold letters,
    digits, `_` and `-` only. taken: the names in use, read once for many robots (else asked of the database).
    """
    base = robot_name_from(re.sub(r"[^0-9A-Za-z_-]+", "_", name or model or "robot").strip("_-"))
    in_use = taken.__contains__ if taken is not None else lambda n: Robot.objects.filter(name=n).exists()
    candidate, n = base, 2
    while in_use(candidate):
        candidate, n = f"{base}_{n}", n + 1
    return candidate


def sync_graph(robot: Robot, graph: Graph, new_rows: Batch | None = None) -> dict:
    """Bring topics, nodes, services and params in line with the graph; return what changed. new_rows: the robot
    is new (it has no rows to compare), its rows wait in the endpoint's batch for batch.insert()."""
    changes = {}
    rows = {
        "topics": (Topic, {n: {"type": t.type, "publishers": t.publishers, "subscribers": t.subscribers}
                           for n, t in graph.topics.items()}),
        "nodes": (Node, graph.nodes),
        "services": (Service, {n: {"type": t} for n, t in {**graph.services, **graph.actions}.items()}),
        "params": (Param, {n: {"value": v if v is not None else ""} for n, v in graph.params.items()}),
    }  # fmt: skip
    for label, (model, wanted) in rows.items():
        if new_rows is not None:
            new_rows.add(model, [model(robot=robot, name=n, **fields) for n, fields in wanted.items()])
            continue
        added, removed, changed = _sync_rows(robot, model, wanted)
        for key, names in (
            (f"{label}_added", added),
            (f"{label}_removed", removed),
            (f"{label}_changed", changed),
        ):
            if names and not (label == "params" and key.endswith("_changed")):
                changes[key] = sorted(names)[:LIST_LIMIT] + (
                    [f"... {len(names)} in all"] if len(names) > LIST_LIMIT else []
                )
    return changes


def _sync_rows(robot: Robot, model, wanted: dict[str, dict]) -> tuple[list, list, list]:
    existing = {row.name: row for row in model.objects.filter(robot=robot)}
    removed = [n for n in existing if n not in wanted]
    if removed:
        model.objects.filter(robot=robot, name__in=removed).delete()
    added = [n for n in wanted if n not in existing]
    model.objects.bulk_create([model(robot=robot, name=n, **wanted[n]) for n in added])
    changed = []
    for name, row in existing.items():
        fields = wanted.get(name)
        if fields and any(getattr(row, f) != v for f, v in fields.items()):
            for f, v in fields.items():
                setattr(row, f, v)
            changed.append(row)
    if changed:
        model.objects.bulk_update(changed, list(next(iter(wanted.values())).keys()))
    return added, removed, [row.name for row in changed]


BINDING_FIELDS = ("target", "kind", "message_type", "how", "confidence", "needs_user", "candidates")


def sync_bindings(
    robot: Robot, graph: Graph, vocab: identify.Vocabulary, new_rows: Batch | None = None
) -> dict:
    """Identify every action, keeping a person's choice while its target exists; return changed bindings.
    new_rows: the robot is new (no bindings yet), its bindings wait in the endpoint's batch."""
    existing = {} if new_rows is not None else {b.action: b for b in Binding.objects.filter(robot=robot)}
    chosen = {a: b.target for a, b in existing.items() if b.how == Binding.How.USER and b.target}
    results = identify.identify(graph, vocab, chosen)
    changed, dropped, new, updated = {}, [], [], []
    now = timezone.now()
    for action, res in results.items():
        old = existing.get(action)
        if action in chosen and res.how != Binding.How.USER:
            dropped.append(f"{action}: {chosen[action]}")
        if old is not None and old.target != res.target:
            changed[action] = [old.target, res.target]
        fields = {name: getattr(res, name) for name in BINDING_FIELDS}
        if old is None:
            new.append(Binding(robot=robot, action=action, updated_at=now, **fields))
        elif any(getattr(old, name) != value for name, value in fields.items()):
            for name, value in fields.items():
                setattr(old, name, value)
            old.updated_at = now  # bulk_update does not apply auto_now
            updated.append(old)
    if new_rows is not None:
        new_rows.add(Binding, new)
    else:
        Binding.objects.bulk_create(new)  # one insert and one update for all the robot's bindings
    Binding.objects.bulk_update(updated, [*BINDING_FIELDS, "updated_at"])
    out = {}
    if changed:
        out["bindings_changed"] = changed
    if dropped:
        out["user_choices_dropped"] = dropped
    return out


def mark_missing(url: str, namespaces: set[str]) -> list[str]:
    """Robots registered from this endpoint that it no longer shows: kept, marked offline."""
    gone = list(Robot.objects.filter(endpoint=url).exclude(namespace__in=namespaces))
    for robot in gone:
        robot.link_status = Robot.Link.OFFLINE
        robot.save(update_fields=["link_status", "updated_at"])
    return [r.name for r in gone]


# ----- vocabulary -----
# Where more topic keywords and synonyms come from (the interpreter adds the ontology's when its app loads).
vocabulary_sources: list[Callable[[identify.Vocabulary], None]] = []


def load_vocabulary() -> identify.Vocabulary:
    """The binding roles' keywords (fleetcore/bindings.py), with what each source adds or replaces."""
    vocab = identify.Vocabulary()
    for source in vocabulary_sources:
        source(vocab)
    return vocab


# ----- presentation -----
def robot_summary(robot: Robot) -> dict:
    """The `register --json` shape of one robot."""
    bindings = {
        b.action: {"topic": b.target, "type": b.message_type, "how": b.how, "confidence": b.confidence}
        for b in robot.bindings.all()
        if b.target
    }
    return {
        "name": robot.name,
        "endpoint": robot.endpoint,
        "namespace": robot.namespace,
        "model": robot.model,
        "drive": robot.drive,
        "wheels": robot.wheel_count,
        "ros_version": robot.ros_version,
        "bindings": bindings,
        "needs_user": sorted(b.action for b in robot.bindings.all() if b.needs_user),
    }
