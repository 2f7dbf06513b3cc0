"""The portal's pages: thin views that authorise, ask the domain and render."""

from django.shortcuts import render

from fleet.models import Instruction, Location, Map
from robots.models import Robot


def dashboard(request):
    """The fleet at a glance: map, robots, instruction console."""
    return render(
        request,
        "fleet/dashboard.html",
        {
            "robots": Robot.objects.all(),
            "maps": Map.objects.all(),
            "locations": Location.objects.select_related("map"),
            "instructions": Instruction.objects.select_related("user")[:20],
        },
    )
