"""Add the cancel action (one instruction taken back) and its synonyms (fleetcore/actions.py) to a database
seeded before them."""

import importlib

from django.db import migrations

registry_actions = importlib.import_module("interpreter.migrations.0003_registry_actions")


class Migration(migrations.Migration):
    dependencies = [("interpreter", "0005_release")]

    operations = [migrations.RunPython(registry_actions.add_missing, migrations.RunPython.noop)]
