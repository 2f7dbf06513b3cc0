"""What the places app tells the apps above it (they connect receivers; places never imports them)."""

from django.dispatch import Signal

# Sent after a world's map and locations are stored, with world (fleetcore.world.World) and map_row (Map).
# Receivers return how many time slots they attached (execution attaches the world's schedules).
world_loaded = Signal()
