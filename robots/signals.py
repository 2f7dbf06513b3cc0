"""What the robots app tells the apps above it (they connect receivers; robots never imports them)."""

from django.dispatch import Signal

# Sent after a registration stored at least one robot, with robots (the names registered).
robots_registered = Signal()
