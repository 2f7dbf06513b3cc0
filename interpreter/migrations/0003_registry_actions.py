"""Add the registry's actions and synonyms a database seeded before them lacks (relative moves, waits, loops,
questions); terms a person edited are left as they are."""

import uuid

from django.db import migrations

from interpreter.terms import seed_terms


def add_missing(apps, schema_editor):
    ActionConcept = apps.get_model("interpreter", "ActionConcept")
    DestinationClass = apps.get_model("interpreter", "DestinationClass")
    Synonym = apps.get_model("interpreter", "Synonym")
    if not ActionConcept.objects.exists():
        return  # not seeded (0002 found terms of its own or none): nothing to complete
    terms = seed_terms()
    classes = {c.name: c for c in DestinationClass.objects.all()}
    added = False
    for a in terms.actions:
        if ActionConcept.objects.filter(name=a.name).exists():
            continue
        row = ActionConcept.objects.create(
            name=a.name, category=a.category, takes_destination=a.takes_destination,
            requires_destination=a.requires_destination, countable=a.countable, description=a.description,
        )  # fmt: skip
        row.accepts.set([classes[n] for n in a.accepts if n in classes])
        added = True
    actions = {a.name: a for a in ActionConcept.objects.all()}
    for s in terms.synonyms:
        if s.action in actions and not Synonym.objects.filter(word=s.word).exists():
            Synonym.objects.create(word=s.word, action=actions[s.action])
            added = True
    if added:
        Version = apps.get_model("interpreter", "OntologyVersion")
        row, _ = Version.objects.get_or_create(pk=1)
        row.number += 1
        row.token = uuid.uuid4().hex
        row.save()


class Migration(migrations.Migration):
    dependencies = [("interpreter", "0002_seed_terms")]

    operations = [migrations.RunPython(add_missing, migrations.RunPython.noop)]
