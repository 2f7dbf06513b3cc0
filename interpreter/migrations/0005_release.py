"""Add the release action (a stop's hold let go) and its synonyms (fleetcore/actions.py) to a database seeded
before them."""

import importlib

from django.db import migrations

registry_actions = importlib.import_module("interpreter.migrations.0003_registry_actions")


class Migration(migrations.Migration):
    dependencies = [("interpreter", "0004_make_way")]

    operations = [migrations.RunPython(registry_actions.add_missing, migrations.RunPython.noop)]
