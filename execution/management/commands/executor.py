"""`python manage.py executor`: run the robots this process owns, one asyncio task each, until SIGTERM or Ctrl-C
(execution/executor.py). Run as many as wanted, on one host or several: the robots spread over the live ones."""

import asyncio
import signal

from django.core.management.base import BaseCommand

from execution.executor import Executor
from fleetcore import heartbeat


class Command(BaseCommand):
    help = "Run the waiting work of the robots this executor owns (rendezvous over the live executors)."

    def handle(self, *args, **options):
        asyncio.run(self.main())

    async def main(self) -> None:
        """The executor on this loop, with the process's heartbeat beaten by the same loop (a blocked loop is
        seen as hung by fleet/hangwatch.py); SIGTERM and SIGINT stop it cleanly."""
        beat = heartbeat.from_env()
        beating = beat.start_task() if beat else None
        executor = Executor()
        loop = asyncio.get_running_loop()
        for signum in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(signum, executor.stop)
        self.stdout.write(f"executor {executor.name} running (Ctrl-C to stop)")
        try:
            await executor.run()
        finally:
            if beating is not None:
                beating.cancel()
        self.stdout.write(f"executor {executor.name} stopped")
