"""Register rosbridge endpoints: discover, identify, store robots and their graph, record what changed.

Endpoints are discovered concurrently (one asyncio loop, one connection each); each endpoint's result is
stored in its own transaction, so one endpoint that fails (unreachable, not rosbridge, silent, garbage)
gives a one-line error for that endpoint while the others register. Re-registration updates rows in place,
keyed by (endpoint, namespace); a person's binding choice survives while its target still exists.
"""

from __future__ import annotations

import asyncio
import logging
import re
from collections.abc import Callable
from dataclasses import dataclass, field

from django.db import transaction
from django.utils import timezone

from audit import records as audit
from robots import identify, kinematics
from robots.discovery import Graph, discover
from robots.models import Binding, Node, Param, RegistrationRecord, Robot, Service, Topic, robot_name_from
from robots.rosbridge import RosbridgeClient, RosbridgeError
from robots.signals import robots_registered

log = logging.getLogger("robots.registration")
ENDPOINT_TIMEOUT = 15.0  # a whole endpoint's discovery, beyond the per-call timeouts
LIST_LIMIT = 50  # names kept per change list in RegistrationRecord.changes


@dataclass
class EndpointResult:
    url: str
    ok: bool = False
    error: str = ""
    robots: list[str] = field(default_factory=list)
    changes: dict = field(default_factory=dict)
    record_id: int | None = None


# ----- discovery (async, no database) -----
async def discover_one(url: str, call_timeout: float = 3.0) -> list[Graph] | RosbridgeError:
    """Discover one endpoint; failures come back as the error, never raised."""
    client = RosbridgeClient(url, call_timeout=call_timeout)
    try:
        await client.connect()
        return await asyncio.wait_for(discover(url, client), ENDPOINT_TIMEOUT)
    except RosbridgeError as exc:
        return exc
    except TimeoutError:
        return RosbridgeError(f"{url}: discovery took longer than {ENDPOINT_TIMEOUT:g} s")
    finally:
        await client.close()


async def discover_all(urls: list[str], call_timeout: float = 3.0) -> list[list[Graph] | RosbridgeError]:
    return await asyncio.gather(*(discover_one(u, call_timeout) for u in urls))


# ----- the entry point -----
def register_endpoints(urls: list[str], user=None, call_timeout: float = 3.0) -> list[EndpointResult]:
    """Register every endpoint (concurrently); return one result per URL, in order."""
    urls = list(dict.fromkeys(u.strip() for u in urls if u and u.strip()))
    found = asyncio.run(discover_all(urls, call_timeout))
    return store_all(urls, found, user)


def store_all(urls: list[str], found: list, user=None) -> list[EndpointResult]:
    """Store discovered graphs (or errors) and attach the current world's schedules."""
    vocab = load_vocabulary()
    results = [store_endpoint(url, graphs, vocab, user) for url, graphs in zip(urls, found, strict=True)]
    registered = [robot for result in results if result.ok for robot in result.robots]
    if registered:
        robots_registered.send(sender=Robot, robots=registered)
    return results


def store_endpoint(url: str, graphs, vocab: identify.Vocabulary, user=None) -> EndpointResult:
    record = RegistrationRecord.objects.create(endpoint=url, user=user if _real(user) else None)
    result = EndpointResult(url, record_id=record.pk)
    if isinstance(graphs, BaseException):
        result.error = str(graphs) or type(graphs).__name__
    else:
        with transaction.atomic():
            for graph in graphs:
                robot, changes = store_robot(url, graph, vocab)
                result.robots.append(robot.name)
                if changes:
                    result.changes[robot.name] = changes
            missing = mark_missing(url, {g.namespace for g in graphs})
            if missing:
                result.changes["missing_robots"] = missing
        result.ok = True
    record.ok, record.error, record.robots, record.changes = (
        result.ok,
        result.error,
        result.robots,
        result.changes,
    )
    record.finished_at = timezone.now()
    record.save()
    audit.record(user, "register", url, ok=result.ok, robots=result.robots, error=result.error)
    return result


def _real(user) -> bool:
    return getattr(user, "is_authenticated", False)


# ----- one robot -----
def store_robot(url: str, graph: Graph, vocab: identify.Vocabulary) -> tuple[Robot, dict]:
    """Create or update one robot and its graph; return it with the changes."""
    robot = Robot.objects.filter(endpoint=url, namespace=graph.namespace).first()
    changes: dict = {}
    model = kinematics.guess_model(graph)
    if robot is None:
        robot = Robot(endpoint=url, namespace=graph.namespace, name=unique_name(graph.name, model))
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
    graph_changes = sync_graph(robot, graph)
    binding_changes = sync_bindings(robot, graph, vocab)
    if not changes:  # a new robot's whole graph is "added": record only what changed on re-registration
        changes.update(graph_changes, **binding_changes)
    return robot, changes


def unique_name(name: str, model: str = "") -> str:
    """The robot's name, else its model's (or "robot"), then `_2`, `_3`... if taken: never a host or port.

    Names are words of the instructions people type ("move turtlebot3_burger_2 to A"), so they hold letters,
    digits, `_` and `-` only.
    """
    base = robot_name_from(re.sub(r"[^0-9A-Za-z_-]+", "_", name or model or "robot").strip("_-"))
    candidate, n = base, 2
    while Robot.objects.filter(name=candidate).exists():
        candidate, n = f"{base}_{n}", n + 1
    return candidate


def sync_graph(robot: Robot, graph: Graph) -> dict:
    """Bring topics, nodes, services and params in line with the graph; return what changed."""
    changes = {}
    rows = {
        "topics": (Topic, {n: {"type": t.type, "publishers": t.publishers, "subscribers": t.subscribers}
                           for n, t in graph.topics.items()}),
        "nodes": (Node, graph.nodes),
        "services": (Service, {n: {"type": t} for n, t in {**graph.services, **graph.actions}.items()}),
        "params": (Param, {n: {"value": v if v is not None else ""} for n, v in graph.params.items()}),
    }  # fmt: skip
    for label, (model, wanted) in rows.items():
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


def sync_bindings(robot: Robot, graph: Graph, vocab: identify.Vocabulary) -> dict:
    """Identify every action, keeping a person's choice while its target exists; return changed bindings."""
    existing = {b.action: b for b in Binding.objects.filter(robot=robot)}
    chosen = {a: b.target for a, b in existing.items() if b.how == Binding.How.USER and b.target}
    results = identify.identify(graph, vocab, chosen)
    changed, dropped = {}, []
    for action, res in results.items():
        old = existing.get(action)
        if action in chosen and res.how != Binding.How.USER:
            dropped.append(f"{action}: {chosen[action]}")
        if old is not None and old.target != res.target:
            changed[action] = [old.target, res.target]
        Binding.objects.update_or_create(
            robot=robot,
            action=action,
            defaults={
                "target": res.target,
                "kind": res.kind,
                "message_type": res.message_type,
                "how": res.how,
                "confidence": res.confidence,
                "needs_user": res.needs_user,
                "candidates": res.candidates,
            },
        )
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
