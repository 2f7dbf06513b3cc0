"""Import a ROS map_server map (YAML + PGM) into the fleet database."""

from django.core.management.base import BaseCommand, CommandError

from fleetcore.mapfile import MapFormatError, load_map
from places.models import Map


class Command(BaseCommand):
    help = "Import (or replace) a map from a ROS map_server YAML file and its image."

    def add_arguments(self, parser):
        parser.add_argument("name", help="the map's name in the portal")
        parser.add_argument("yaml_path", help="map_server YAML, e.g. maps/office.yaml")

    def handle(self, *args, name, yaml_path, **options):
        try:
            grid = load_map(yaml_path)
        except (MapFormatError, OSError) as exc:
            raise CommandError(str(exc)) from None
        fresh = Map.from_grid(name, grid, source=str(yaml_path))
        fields = ("resolution", "width", "height", "origin_x", "origin_y", "origin_yaw", "data", "source")
        row, created = Map.objects.update_or_create(
            name=name, defaults={field: getattr(fresh, field) for field in fields}
        )
        verb = "imported" if created else "replaced"
        self.stdout.write(f"{verb} map {row.name!r}: {row.width}x{row.height} cells at {row.resolution} m")
