"""Read the acceptance table of instructions (tests/data/instructions.tsv: text -> expected parse)."""

import csv
from pathlib import Path

TSV = Path(__file__).resolve().parents[1] / "data" / "instructions.tsv"
COLUMNS = ["text", "type", "needs_user", "action", "robots", "destination", "task", "steps"]


def rows() -> list[dict]:
    lines = [
        line for line in TSV.read_text(encoding="utf-8").splitlines() if line and not line.startswith("#")
    ]
    reader = csv.DictReader(lines, delimiter="\t")
    assert reader.fieldnames == COLUMNS, reader.fieldnames
    return list(reader)


def summary(result: dict) -> dict:
    """Put an interpreter result in the table's columns."""
    first = result["steps"][0] if result["steps"] else {}
    robots = first.get("robots", "any")
    return {
        "type": result["type"],
        "needs_user": "yes" if result["needs_user"] else "no",
        "action": first.get("action") or "-",
        "robots": _robots(robots),
        "destination": (first.get("destination") or {}).get("name", "-"),
        "task": first.get("task") or "-",
        "steps": str(len(result["steps"])),
    }


def _robots(robots) -> str:
    """ "any", "all", "husky,tiago", or a subject object in words: "any turtlebot", "all except husky"."""
    if isinstance(robots, str):
        return robots
    if isinstance(robots, dict):
        words = ["all" if robots.get("all") else "any"]
        words += [robots["model"]] if robots.get("model") else []
        words += [f"except {'+'.join(robots['except'])}"] if robots.get("except") else []
        return " ".join(words)
    return ",".join(robots)
