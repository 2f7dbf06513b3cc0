"""`python manage.py scheduler`: the loop that watches executors and runs schedules (SIGTERM stops it cleanly)."""

import datetime
import signal

from django.core.management.base import BaseCommand, CommandError
from django.utils import timezone

from execution.scheduler import Clock, loop
from fleetcore import heartbeat


class Command(BaseCommand):
    help = "Stop the robots of lost executors (every 0.25 s), run time slots, restart stalled queues, sweep."

    def add_arguments(self, parser):
        parser.add_argument("--period", type=float, default=0.5, help="seconds between ticks")
        parser.add_argument("--clock-start", help="start a compressed clock at this local time (HH:MM)")
        parser.add_argument(
            "--clock-scale", type=float, default=1.0, help="compressed clock speed (e.g. 600)"
        )

    def handle(self, *args, period, clock_start, clock_scale, **options):
        clock = Clock()
        if clock_start:
            try:
                at = datetime.time.fromisoformat(clock_start)
            except ValueError:
                raise CommandError(f"--clock-start: expected HH:MM, got {clock_start!r}") from None
            today = timezone.localdate()
            start = timezone.make_aware(datetime.datetime.combine(today, at))
            clock = Clock(start, clock_scale)
        stopping = []
        signal.signal(signal.SIGTERM, lambda *_: stopping.append(True))
        signal.signal(signal.SIGINT, lambda *_: stopping.append(True))
        self.stdout.write(f"scheduler running (tick {period:g} s)")
        beat = heartbeat.from_env()
        loop(clock, period, should_stop=lambda: bool(stopping), beat=beat.beat if beat else lambda: None)
