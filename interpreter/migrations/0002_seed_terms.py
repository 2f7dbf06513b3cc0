"""Seed the ontology's terms: the paper's actions, synonyms (section 3.4), destinations and topic keywords."""

import types
import uuid

from django.db import migrations

from interpreter.service import write_terms
from interpreter.terms import seed_terms

MODELS = ("DestinationClass", "ActionConcept", "DestinationConcept", "Synonym", "TopicKeyword")


def seed(apps, schema_editor):
    models = types.SimpleNamespace(**{name: apps.get_model("interpreter", name) for name in MODELS})
    if models.ActionConcept.objects.exists():
        return
    write_terms(seed_terms(), models)
    apps.get_model("interpreter", "OntologyVersion").objects.update_or_create(
        pk=1, defaults={"number": 1, "token": uuid.uuid4().hex}
    )


def unseed(apps, schema_editor):
    for name in ("Synonym", "DestinationConcept", "ActionConcept", "TopicKeyword"):
        apps.get_model("interpreter", name).objects.all().delete()
    DestinationClass = apps.get_model("interpreter", "DestinationClass")
    DestinationClass.objects.update(parent=None)
    DestinationClass.objects.all().delete()


class Migration(migrations.Migration):
    dependencies = [("interpreter", "0001_ontology_terms")]

    operations = [migrations.RunPython(seed, unseed)]
