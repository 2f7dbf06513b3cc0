"""Execution.queued_at: its place in the robot's queue, which a person may move (execution/tasklist.py); a
queue kept before it is in creation order, so it starts as created_at."""

import django.utils.timezone
from django.db import migrations, models


def from_created(apps, schema_editor):
    Execution = apps.get_model("execution", "Execution")
    Execution.objects.update(queued_at=models.F("created_at"))


class Migration(migrations.Migration):
    dependencies = [
        ("execution", "0002_instruction_cause"),
    ]

    operations = [
        migrations.AddField(
            model_name="execution",
            name="queued_at",
            field=models.DateTimeField(
                default=django.utils.timezone.now,
                help_text="its place in the robot's queue (oldest first); moved up or down by a person",
            ),
        ),
        migrations.RunPython(from_created, migrations.RunPython.noop),
        migrations.AddIndex(
            model_name="execution",
            index=models.Index(
                fields=["robot", "status", "queued_at"], name="execution_e_robot_i_bb1081_idx"
            ),
        ),
    ]
