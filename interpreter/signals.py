"""Bump the ontology or fleet version whenever a term, a robot or a location changes."""

from django.db.models.signals import m2m_changed, post_delete, post_save
from django.dispatch import receiver

from interpreter import versions

_TERM_MODELS = (
    "interpreter.ActionConcept",
    "interpreter.DestinationClass",
    "interpreter.DestinationConcept",
    "interpreter.Synonym",
    "interpreter.TopicKeyword",
)
_FLEET_MODELS = ("robots.Robot", "places.Location")


def _on_term_change(sender, **kwargs):
    versions.bump_ontology()


_NAMING_FIELDS = {"name", "model", "drive", "x", "y", "kind"}


def _on_fleet_change(sender, update_fields=None, **kwargs):
    if update_fields is None or set(update_fields) & _NAMING_FIELDS:
        versions.bump_fleet()


for _label in _TERM_MODELS:
    post_save.connect(_on_term_change, sender=_label, dispatch_uid=f"ontology-save-{_label}")
    post_delete.connect(_on_term_change, sender=_label, dispatch_uid=f"ontology-delete-{_label}")
for _label in _FLEET_MODELS:
    post_save.connect(_on_fleet_change, sender=_label, dispatch_uid=f"fleet-save-{_label}")
    post_delete.connect(_on_fleet_change, sender=_label, dispatch_uid=f"fleet-delete-{_label}")


@receiver(m2m_changed, sender="interpreter.ActionConcept_accepts", dispatch_uid="ontology-accepts")
def _on_accepts_change(sender, action, **kwargs):
    if action in {"post_add", "post_remove", "post_clear"}:
        versions.bump_ontology()
