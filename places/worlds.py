"""Load a simulator world's map, locations and schedules into the fleet database."""

import datetime

from django.conf import settings
from django.db import transaction

from execution.models import TimeSlot
from places.models import Location, Map
from robots.models import Robot


@transaction.atomic
def load_world_into_db(name: str) -> str:
    """Create or update the world's map and locations; schedules for the robots already registered."""
    from fleetcore.world import load_world

    world = load_world(name)
    fresh = Map.from_grid(world.name, world.map, source=f"fleetcore/worlds/{world.name}")
    map_row, _ = Map.objects.update_or_create(
        name=world.name,
        defaults={
            field: getattr(fresh, field)
            for field in (
                "resolution",
                "width",
                "height",
                "origin_x",
                "origin_y",
                "origin_yaw",
                "data",
                "source",
            )
        },
    )
    for spec in world.locations:
        Location.objects.update_or_create(
            map=map_row,
            name=spec.name,
            defaults={"x": spec.x, "y": spec.y, "yaw": spec.yaw, "kind": spec.kind},
        )
    slots = load_schedules(world, map_row)
    return f"map {map_row.width}x{map_row.height} cells, {len(world.locations)} locations, {slots} time slots"


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
