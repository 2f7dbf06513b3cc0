"""Template filters that show stored values (JSON details, facts) as words a person reads, not Python reprs."""

from django import template

register = template.Library()

EMPTY = "–"


def readable(value) -> str:
    """One value as text: lists joined with commas, mappings as "key: value" pairs, booleans as yes/no."""
    if value is None or value == "" or value == [] or value == {}:
        return EMPTY
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        return f"{value:g}"
    if isinstance(value, list | tuple | set):
        return ", ".join(readable(item) for item in value)
    if isinstance(value, dict):
        return "; ".join(f"{label(key)}: {readable(item)}" for key, item in value.items())
    return str(value)


def label(key) -> str:
    """A details key as words: `taken_over_from` reads "taken over from"."""
    return str(key).replace("_", " ")


@register.filter(name="readable")
def readable_filter(value) -> str:
    return readable(value)


@register.filter
def readable_items(details) -> list[tuple[str, str]]:
    """A details mapping as (label, text) pairs, in stored order; anything else as one unlabelled pair."""
    if not isinstance(details, dict):
        return [("", readable(details))]
    return [(label(key), readable(value)) for key, value in details.items()]
