"""The management commands `interpret` and `ontology`, and the JSON API."""

import io
import json

import pytest
from django.core.management import CommandError, call_command

from fleetcore.actions import ACTIONS
from interpreter.models import Synonym

from .acceptance import rows

pytestmark = pytest.mark.django_db


def run(*args, stdin=None, monkeypatch=None) -> str:
    out = io.StringIO()
    call_command(*args, stdout=out, stderr=io.StringIO())
    return out.getvalue()


def test_interpret_json_prints_one_object(paper_world):
    result = json.loads(run("interpret", "--json", "Move to A and clean"))
    assert result["type"] == "I" and result["steps"][0]["task"] == "clean"


def test_interpret_file_prints_one_object_per_line(paper_world, tmp_path):
    path = tmp_path / "lines.txt"
    path.write_text("\n".join(r["text"] for r in rows()) + "\n\n", encoding="utf-8")
    lines = run("interpret", "--file", str(path)).splitlines()
    assert [json.loads(line)["type"] for line in lines] == [r["type"] for r in rows()]


def test_interpret_reads_stdin(paper_world, monkeypatch):
    monkeypatch.setattr("sys.stdin", io.StringIO("stop\nGo to C\n"))
    assert [json.loads(x)["type"] for x in run("interpret", "--file", "-").splitlines()] == ["I", "II"]


def test_interpret_needs_text_or_file(db):
    with pytest.raises(CommandError):
        call_command("interpret")
    with pytest.raises(CommandError, match="cannot read"):
        call_command("interpret", "--file", "/nonexistent/file")


def test_ontology_export_then_import_restores_the_terms(paper_world, tmp_path):
    path = tmp_path / "robots.owl"
    call_command("ontology", "export", str(path), stderr=io.StringIO())
    before = sorted(Synonym.objects.values_list("word", flat=True))
    Synonym.objects.all().delete()
    out = run("ontology", "import", str(path))
    assert f"imported {len(ACTIONS)} actions" in out
    assert sorted(Synonym.objects.values_list("word", flat=True)) == before


def test_ontology_import_of_a_bad_file_fails_clearly(db, tmp_path):
    path = tmp_path / "bad.owl"
    path.write_text("hello")
    with pytest.raises(CommandError, match="cannot read the ontology"):
        call_command("ontology", "import", str(path))


def test_api_interpret_and_teach(paper_world, operator, client_for):
    client = client_for(operator)
    response = client.post(
        "/api/interpreter/interpret", {"text": "scoot to A"}, content_type="application/json"
    )
    assert response.status_code == 200 and response.json()["type"] == "V"
    response = client.post(
        "/api/interpreter/teach", {"answer": "scoot means move"}, content_type="application/json"
    )
    assert response.status_code == 200 and response.json()["ok"]
    response = client.post(
        "/api/interpreter/interpret", {"text": "scoot to A"}, content_type="application/json"
    )
    assert response.json()["type"] == "II"
