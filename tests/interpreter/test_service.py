"""The interpreter service with the database: acceptance rows, teaching, edits without a restart."""

import pytest

from audit.models import AuditEntry
from execution.models import Instruction
from interpreter import versions
from interpreter.models import ActionConcept, DestinationConcept, Lesson, Synonym
from interpreter.service import interpret, store, teach, warm_up
from places.models import Location

from .acceptance import rows, summary

pytestmark = pytest.mark.django_db


@pytest.mark.parametrize("row", rows(), ids=lambda r: r["text"])
def test_acceptance_row_through_the_database(paper_world, row):
    expected = {k: v for k, v in row.items() if k != "text"}
    assert summary(interpret(row["text"]).to_dict()) == expected


def test_destination_carries_the_map_coordinates(paper_world):
    step = interpret("move turtlebot to D").to_dict()["steps"][0]
    assert step["destination"] == {"name": "D", "x": 5.0, "y": 5.0}


def test_ontology_is_built_once_then_reused(paper_world):
    for _ in range(5):
        interpret("move husky to A")
    assert store().builds == 1


def test_teaching_a_synonym_takes_effect_on_the_next_instruction(paper_world, operator):
    assert interpret("scoot husky to A").to_dict()["type"] == "V"
    result = teach("scoot means move", operator)
    assert result["ok"], result
    after = interpret("scoot husky to A").to_dict()
    assert after["type"] == "II" and after["synonyms_used"] == {"scoot": "move"}
    lesson = Lesson.objects.get()
    assert (lesson.taught_by, lesson.word, lesson.meaning, lesson.kind) == (
        operator,
        "scoot",
        "move",
        "synonym",
    )
    audit = AuditEntry.objects.get(action="ontology.teach")
    assert audit.user == operator and audit.target == "scoot"


def test_sea_is_not_a_place_turns_type_v_into_type_iv(paper_world, operator):
    instruction = Instruction.objects.create(text="Proceed to sea and clean", user=operator)
    assert interpret(instruction.text).to_dict()["type"] == "V"
    result = teach("sea is not a place", operator, instruction=instruction.pk)
    assert result["ok"] and result["instruction"]["type"] == "IV"
    assert Lesson.objects.get().instruction == instruction


def test_teaching_a_location_makes_it_a_destination(paper_world, operator):
    assert teach("sea is a location at (3, 4)", operator)["ok"]
    assert Location.objects.filter(name="sea", x=3, y=4).exists()
    step = interpret("move husky to the sea").to_dict()["steps"][0]
    assert step["destination"] == {"name": "sea", "x": 3.0, "y": 4.0}


def test_forget_undoes_a_synonym(paper_world, operator):
    teach("scoot means move", operator)
    assert teach("forget scoot", operator)["ok"]
    assert interpret("scoot husky to A").to_dict()["type"] == "V"


@pytest.mark.parametrize(
    "answer",
    ["move means stop", "blorp means frobnicate", "what?", "husky is not a place", "shift means move"],
)
def test_bad_answers_are_refused_with_a_reason(paper_world, operator, answer):
    result = teach(answer, operator)
    assert not result["ok"] and result["message"] and result["examples"]
    assert not Lesson.objects.exists()


def test_admin_edit_takes_effect_without_restart(paper_world, fleet_admin, client_for):
    interpret("move husky to A")
    client = client_for(fleet_admin)
    move = ActionConcept.objects.get(name="move")
    response = client.post(
        "/admin/interpreter/synonym/add/", {"word": "zoom", "action": move.pk, "concept": ""}
    )
    assert response.status_code == 302, response.content[:500]
    assert interpret("zoom husky to A").to_dict()["synonyms_used"] == {"zoom": "move"}


def test_edits_reach_other_processes_through_the_cache(paper_world, django_capture_on_commit_callbacks):
    """Another process only sees the cache token: an edit must change it once committed."""
    interpret("move husky to A")
    before = versions.current()[0]
    roof_class = DestinationConcept.objects.get(name="roof").destination_class
    with django_capture_on_commit_callbacks(execute=True):
        DestinationConcept.objects.create(name="lava", destination_class=roof_class)
    assert versions.current()[0] != before
    store().local_changes.clear()  # as if in another process: only the token tells
    assert interpret("move husky to lava").to_dict()["type"] == "III"


def test_new_robots_and_locations_are_seen_at_once(paper_world):
    from robots.models import Robot

    assert interpret("move robot9 to A").to_dict()["type"] == "V"
    Robot.objects.create(name="robot9", model="husky", drive="wheeled", endpoint="ws://127.0.0.1:9999")
    assert interpret("move robot9 to A").to_dict()["steps"][0]["robots"] == ["robot9"]
    Location.objects.create(map=paper_world, name="Kitchen", x=1, y=2, kind="room")
    assert interpret("move robot9 to the kitchen").to_dict()["steps"][0]["destination"]["name"] == "Kitchen"


def test_synonym_edit_in_the_database_changes_the_type(paper_world):
    Synonym.objects.filter(word="shift").delete()
    assert interpret("Shift to B and clean").to_dict()["type"] == "V"


def test_warm_up_builds_the_snapshot(paper_world):
    warm_up()
    assert store().lexicon is not None
