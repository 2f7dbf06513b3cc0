"""A world's daily time slots attached to the robots registered under their names (on world load and on
registration: receivers of places.signals.world_loaded and robots.signals.robots_registered)."""

import datetime
import logging

from django.conf import settings

from execution.models import TimeSlot
from fleetcore.world import WorldFormatError, load_world
from places.models import Location, Map
from robots.models import Robot

log = logging.getLogger(__name__)


def on_world_loaded(sender, world, map_row, **_kwargs) -> int:
    return load_schedules(world, map_row)


def on_robots_registered(sender, robots, **_kwargs) -> int:
    return attach_world_schedules()


def attach_world_schedules() -> int:
    """Attach the current world's time slots to robots now registered, if its map is loaded."""
    name = getattr(settings, "FLEET_WORLD", "")
    map_row = Map.objects.filter(name=name).first() if name else None
    if map_row is None:
        return 0
    try:
        world = load_world(name)
    except (OSError, ValueError, WorldFormatError) as exc:
        log.warning("world %s: schedules not attached (%s)", name, exc)
        return 0
    return load_schedules(world, map_row)


def load_schedules(world, map_row: Map) -> int:
    """Create the world's time slots for robots registered under those names (idempotent)."""
    created = 0
    robots = {
        robot.name: robot for robot in Robot.objects.filter(name__in={s.robot for s in world.schedules})
    }
    for spec in world.schedules:
        robot = robots.get(spec.robot)
        if robot is None:
            continue
        _, was_created = TimeSlot.objects.get_or_create(
            robot=robot,
            start=datetime.time.fromisoformat(spec.start),
            end=datetime.time.fromisoformat(spec.end),
            defaults={
                "goal": Location.objects.get(map=map_row, name=spec.goal),
                "task": spec.task,
                "enabled": settings.FLEET_DEMO_SCHEDULES,
            },
        )
        created += was_created
    return created
