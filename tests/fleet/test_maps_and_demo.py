"""Maps come from ROS map_server files; the demo world loads into the database."""

from pathlib import Path

import pytest
from django.core.management import CommandError, call_command

from execution.models import TimeSlot
from places.models import Location, Map
from places.worlds import load_world_into_db
from robots.models import Robot

PAPER_MAP = Path(__file__).resolve().parents[2] / "fleetcore" / "worlds" / "paper" / "map.yaml"


@pytest.mark.django_db
def test_import_map_stores_the_grid_as_map_server_reads_it():
    call_command("import_map", "office", str(PAPER_MAP))
    row = Map.objects.get(name="office")
    from fleetcore.mapfile import load_map

    grid = load_map(PAPER_MAP)
    assert (row.width, row.height, row.resolution) == (grid.width, grid.height, grid.resolution)
    assert row.cells() == list(grid.data)
    assert set(row.cells()) <= {-1, 0, 100}


@pytest.mark.django_db
def test_import_map_reports_a_bad_file_and_keeps_the_old_map(tmp_path):
    call_command("import_map", "office", str(PAPER_MAP))
    bad = tmp_path / "bad.yaml"
    bad.write_text("image: missing.pgm\nresolution: 0.05\n")
    with pytest.raises(CommandError, match=r"bad\.yaml"):
        call_command("import_map", "office", str(bad))
    assert Map.objects.get(name="office").width > 0


@pytest.mark.django_db
def test_demo_world_loads_map_locations_and_is_idempotent():
    load_world_into_db("paper")
    load_world_into_db("paper")
    names = set(Location.objects.values_list("name", flat=True))
    assert {"A", "B", "C", "D", "E", "F", "G", "H", "I", "Room 1", "Room 2", "Room 3", "Room 4"} <= names
    assert Location.objects.count() == len(names)
    assert Location.objects.get(name="D").x == 5.0
    assert Location.objects.get(name="Room 3").kind == Location.Kind.ROOM


@pytest.mark.django_db
def test_table_12_slots_attach_to_registered_robots():
    for name in ("turtlebot", "husky", "tiago"):
        Robot.objects.create(name=name, endpoint=f"ws://127.0.0.1/{name}")
    load_world_into_db("paper")
    assert TimeSlot.objects.filter(robot__name="husky").count() >= 1
    assert not TimeSlot.objects.filter(
        enabled=True
    ).exists()  # demo slots start disabled (FLEET_DEMO_SCHEDULES)


@pytest.mark.django_db
def test_setup_demo_names_an_unknown_world_in_one_line_and_loads_nothing(settings, tmp_path):
    settings.VAR_DIR = tmp_path  # the demo admin's password file goes here
    with pytest.raises(
        CommandError, match=r"world 'nowhere' \(--world or FLEET_WORLD\): .*cannot read world"
    ):
        call_command("setup_demo", world="nowhere")
    assert not Map.objects.exists() and not Location.objects.exists()
