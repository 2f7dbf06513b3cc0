"""History exported as CSV and JSON with the page's filters (portal/exports.py)."""

import csv
import io

from execution.models import Instruction
from robots.models import Robot


def _history(operator):
    husky = Robot.objects.create(name="husky", endpoint="ws://127.0.0.1:1")
    tiago = Robot.objects.create(name="tiago", endpoint="ws://127.0.0.1:2")
    first = Instruction.objects.create(text="move husky to A", user=operator, status="cancelled",
                                       outcome="husky: cancelled (cancelled by otto)")  # fmt: skip
    first.robots.set([husky])
    second = Instruction.objects.create(text="=HYPERLINK(1)", user=operator, status="cancelled")
    second.robots.set([husky])
    other = Instruction.objects.create(text="move tiago to B", user=operator, status="succeeded")
    other.robots.set([tiago])
    return first, second, other


def test_the_csv_export_has_the_filtered_rows(client_for, operator):
    first, second, _ = _history(operator)
    response = client_for(operator).get(
        "/history/", {"status": "cancelled", "robot": "husky", "format": "csv"}
    )
    assert response.status_code == 200 and response["Content-Type"].startswith("text/csv")
    assert 'filename="history.csv"' in response["Content-Disposition"]
    rows = list(csv.DictReader(io.StringIO(response.content.decode())))
    assert {row["id"] for row in rows} == {str(first.pk), str(second.pk)}
    by_id = {row["id"]: row for row in rows}
    assert by_id[str(first.pk)]["outcome"] == "husky: cancelled (cancelled by otto)"
    assert by_id[str(first.pk)]["robots"] == "husky" and by_id[str(first.pk)]["user"] == "otto"
    assert by_id[str(second.pk)]["text"] == "'=HYPERLINK(1)"  # shown by a spreadsheet, not run


def test_the_json_export_has_the_filtered_rows(client_for, viewer, operator):
    _, _, other = _history(operator)
    response = client_for(viewer).get("/history/", {"q": "tiago", "format": "json"})
    assert response.status_code == 200
    rows = response.json()
    assert [(row["id"], row["status"], row["robots"]) for row in rows] == [(other.pk, "succeeded", ["tiago"])]
    assert rows[0]["received_at"]


def test_the_page_links_its_exports_with_its_filters(client_for, operator):
    _history(operator)
    page = client_for(operator).get("/history/", {"status": "cancelled"}).content.decode()
    assert 'href="?status=cancelled&amp;format=csv"' in page
