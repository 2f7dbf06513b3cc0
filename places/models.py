"""Places robots go: occupancy-grid maps and the named locations on them."""

from django.db import models
from django.utils import timezone


class Map(models.Model):
    """An occupancy grid in ROS map_server terms (cell (0, 0) at the lower left, row-major)."""

    name = models.CharField(max_length=100, unique=True)
    resolution = models.FloatField(help_text="metres per cell")
    width = models.PositiveIntegerField()
    height = models.PositiveIntegerField()
    origin_x = models.FloatField(default=0.0)
    origin_y = models.FloatField(default=0.0)
    origin_yaw = models.FloatField(default=0.0)
    data = models.BinaryField(help_text="one signed byte per cell: 0 free, 100 occupied, -1 unknown")
    source = models.CharField(max_length=255, blank=True, help_text="the map_server YAML it came from")
    created_at = models.DateTimeField(default=timezone.now)

    class Meta:
        ordering = ["name"]

    def __str__(self):
        return self.name

    @classmethod
    def from_grid(cls, name, grid, source=""):
        """Build (unsaved) from a fleetcore.mapfile.OccupancyGrid."""
        x, y, yaw = grid.origin
        data = bytes(value & 0xFF for value in grid.data)
        return cls(
            name=name,
            resolution=grid.resolution,
            width=grid.width,
            height=grid.height,
            origin_x=x,
            origin_y=y,
            origin_yaw=yaw,
            data=data,
            source=source,
        )

    def cells(self) -> list[int]:
        """The grid as signed ints, as nav_msgs/OccupancyGrid carries it."""
        return [value - 256 if value > 127 else value for value in bytes(self.data)]

    @property
    def extent(self) -> tuple[float, float, float, float]:
        """(min_x, min_y, max_x, max_y) in metres."""
        return (
            self.origin_x,
            self.origin_y,
            self.origin_x + self.width * self.resolution,
            self.origin_y + self.height * self.resolution,
        )


class Location(models.Model):
    class Kind(models.TextChoices):
        ROOM = "room"
        WAYPOINT = "waypoint"

    map = models.ForeignKey(Map, on_delete=models.CASCADE, related_name="locations")
    name = models.CharField(max_length=100)
    x = models.FloatField()
    y = models.FloatField()
    yaw = models.FloatField(default=0.0)
    kind = models.CharField(max_length=10, choices=Kind.choices, default=Kind.WAYPOINT)

    class Meta:
        ordering = ["name"]
        constraints = [models.UniqueConstraint(fields=["map", "name"], name="location_unique_per_map")]

    def __str__(self):
        return self.name
