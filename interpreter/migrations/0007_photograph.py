"""Add the photograph action (a photo from the robot's camera) and its synonyms (fleetcore/actions.py) to a
database seeded before them."""

import importlib

from django.db import migrations

registry_actions = importlib.import_module("interpreter.migrations.0003_registry_actions")


class Migration(migrations.Migration):
    dependencies = [("interpreter", "0006_cancel")]

    operations = [migrations.RunPython(registry_actions.add_missing, migrations.RunPython.noop)]
