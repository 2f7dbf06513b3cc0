"""`python manage.py record --seconds N --out run.mcap [--topic husky:/cmd_vel ...]`: record the fleet to MCAP."""

from pathlib import Path

from django.core.management.base import BaseCommand, CommandError

from recordings import recorder


class Command(BaseCommand):
    help = "Record what the portal pushes (poses, states, instructions, goals, alerts) and chosen raw topics to MCAP."

    def add_arguments(self, parser):
        parser.add_argument("--seconds", type=float, required=True, help="how long to record")
        parser.add_argument(
            "--out", type=Path, help="the MCAP file (default var/recordings/recording-<id>.mcap)"
        )
        parser.add_argument(
            "--topic",
            action="append",
            default=[],
            metavar="ROBOT:/TOPIC",
            help="also a raw Twist topic (repeat)",
        )

    def handle(self, *args, **opts):
        out = opts["out"].resolve() if opts["out"] else None
        if out is not None and not out.parent.is_dir():
            raise CommandError(f"--out: no directory {out.parent}")
        try:
            recording = recorder.create(None, opts["seconds"], opts["topic"], path=out)
        except recorder.RecordingError as exc:
            raise CommandError(str(exc)) from exc
        self.stdout.write(f"recording {opts['seconds']:g} s to {recording.path} …")
        recording = recorder.run(recording.pk)
        if recording.status != recording.Status.FINISHED:
            raise CommandError(f"recording failed: {recording.error}")
        counts = (
            ", ".join(f"{topic} {n}" for topic, n in sorted(recording.counts.items())) or "nothing pushed"
        )
        self.stdout.write(f"wrote {recording.path}: {recording.messages} messages ({counts})")
