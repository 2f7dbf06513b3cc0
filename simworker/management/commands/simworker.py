"""`python manage.py simworker --world paper`: serve a simulated world until SIGINT / SIGTERM."""

from __future__ import annotations

from django.core.management.base import BaseCommand, CommandError

from simworker.runner import serve_world


class Command(BaseCommand):
    help = "Run a simulated fleet: physics plus one rosbridge v2 endpoint per robot group."
    requires_system_checks: list = []  # needs no database: the simulator is plain Python
    requires_migrations_checks = False

    def add_arguments(self, parser):
        parser.add_argument("--world", default="paper", help="world name under fleetcore/worlds or a path")
        parser.add_argument(
            "--extra", type=int, default=0, help="extra namespaced robots on the extra endpoint"
        )
        parser.add_argument(
            "--extra-skip",
            type=int,
            default=0,
            help="a shard's slice of the extra robots: leave out this many first (names and places)",
        )
        parser.add_argument(
            "--extra-spacing",
            type=float,
            help="metres between extra robots (the world's own grid by default)",
        )
        parser.add_argument(
            "--endpoints", help="serve only these endpoints (comma-separated keys, e.g. extra): a shard"
        )
        parser.add_argument("--host", default="127.0.0.1")
        parser.add_argument("--port-base", type=int, default=9090, help="port of endpoint offset 0")
        parser.add_argument("--time-scale", type=float, default=1.0, help="simulated seconds per wall second")
        parser.add_argument(
            "--keep-last-command",
            action="store_true",
            help="robots drive on with their last velocity command for ever, as bases without a cmd_vel "
            "timeout do (the chaos tests: a robot at rest after a fault is then the portal's doing)",
        )

    def handle(self, *args, **opts):
        if opts["extra"] < 0:
            raise CommandError("--extra must be 0 or more")
        try:
            serve_world(
                opts["world"],
                opts["host"],
                opts["port_base"],
                opts["extra"],
                opts["time_scale"],
                opts["keep_last_command"],
                out=lambda line: self.stdout.write(line),
                endpoints=opts["endpoints"].split(",") if opts["endpoints"] else None,
                extra_skip=opts["extra_skip"],
                extra_spacing=opts["extra_spacing"],
            )
        except (OSError, ValueError, KeyError) as exc:
            raise CommandError(str(exc)) from exc
