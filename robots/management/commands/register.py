"""`python manage.py register URL [URL ...] [--json]`: register rosbridge endpoints as robots."""

from __future__ import annotations

import json

from django.core.management.base import BaseCommand, CommandError

from robots.models import Robot
from robots.registration import register_endpoints, robot_summary


class Command(BaseCommand):
    help = "Discover rosbridge endpoints, register their robots and bind each action to a topic."

    def add_arguments(self, parser):
        parser.add_argument(
            "urls", nargs="+", metavar="URL", help="rosbridge WebSocket URL, e.g. ws://10.0.0.5:9090"
        )
        parser.add_argument("--json", action="store_true", help="print the registered robots as JSON")
        parser.add_argument(
            "--timeout", type=float, default=3.0, help="seconds to wait for each rosapi answer"
        )

    def handle(self, *args, **opts):
        results = register_endpoints(opts["urls"], call_timeout=opts["timeout"])
        names = list(dict.fromkeys(name for r in results for name in r.robots))  # aliases name robots twice
        robots = Robot.objects.filter(name__in=names).prefetch_related("bindings")
        by_name = {r.name: r for r in robots}
        if opts["json"]:
            self.stdout.write(
                json.dumps([robot_summary(by_name[n]) for n in names if n in by_name], indent=2)
            )
        else:
            for result in results:
                self._report(result, by_name)
        for result in results:  # one line per endpoint refused, whatever the others did
            if not result.ok:
                self.stderr.write(f"error: {result.error}")
        failed = [r for r in results if not r.ok]
        if failed:
            raise CommandError(f"{len(failed)} of {len(results)} endpoints failed")

    def _report(self, result, by_name) -> None:
        if not result.ok:
            return
        for name in result.robots:
            summary = robot_summary(by_name[name])
            bound = ", ".join(f"{a}={b['topic']}" for a, b in summary["bindings"].items())
            ask = f"; needs a person for {', '.join(summary['needs_user'])}" if summary["needs_user"] else ""
            self.stdout.write(f"{name} ({summary['model'] or 'unknown model'}, {result.url}): {bound}{ask}")
