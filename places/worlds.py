"""Load a simulator world's map, locations and schedules into the fleet database."""

from django.db import transaction

from fleetcore.world import load_world
from places.models import Location, Map
from places.signals import world_loaded


@transaction.atomic
def load_world_into_db(name: str) -> str:
    """Create or update the world's map and locations; schedules for the robots already registered."""
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
    slots = sum(count or 0 for _, count in world_loaded.send(sender=Map, world=world, map_row=map_row))
    return f"map {map_row.width}x{map_row.height} cells, {len(world.locations)} locations, {slots} time slots"
