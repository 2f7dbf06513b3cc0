"""`python manage.py robotlinks [--register-world paper] [--register URL ...]`: keep robot links until SIGTERM."""

from __future__ import annotations

import asyncio
import signal

from asgiref.sync import sync_to_async
from django.core.management.base import BaseCommand, CommandError

from fleetcore import heartbeat
from fleetcore.world import WorldFormatError, load_world
from robots import endpoints, stopsocket
from robots.endpoints import allow_list
from robots.links import LinkManager, battery_hook, wait_for_endpoints
from robots.poses import PoseHub, link_hook
from robots.registration import discover_all, store_all
from robots.rosbridge import RosbridgeError


def world_endpoints(name: str, host: str, port_base: int) -> list[str]:
    """The URLs of a simulator world's endpoints that carry robots."""
    try:
        world = load_world(name)
    except (OSError, WorldFormatError) as exc:
        raise CommandError(str(exc)) from exc
    return world.robot_endpoint_urls(host, port_base)


class Command(BaseCommand):
    help = "Keep one rosbridge link per registered endpoint: robots' online/offline status, live."

    def add_arguments(self, parser):
        parser.add_argument(
            "--register-world", metavar="WORLD", help="first register this simulator world's endpoints"
        )
        parser.add_argument(
            "--register", nargs="+", default=[], metavar="URL", help="first register these endpoints"
        )
        parser.add_argument("--host", default="127.0.0.1", help="host of the world's endpoints")
        parser.add_argument(
            "--port-base", type=int, default=9090, help="port of the world's endpoint offset 0"
        )
        parser.add_argument(
            "--wait", type=float, default=30.0, help="seconds to wait for endpoints to answer"
        )
        parser.add_argument(
            "--only", action="store_true", help="link only the endpoints given here, not every registered one"
        )

    def handle(self, *args, **opts):
        urls = list(opts["register"])
        if opts["register_world"]:
            urls += world_endpoints(opts["register_world"], opts["host"], opts["port_base"])
        if opts["only"] and not urls:
            raise CommandError("--only needs --register or --register-world")
        asyncio.run(self.main(urls, opts["wait"], opts["only"]))

    async def main(self, urls: list[str], wait: float, only: bool) -> None:
        beat = heartbeat.from_env()
        beating = beat.start_task() if beat else None  # renewed by this loop: a blocked loop is seen as hung
        hub = PoseHub()  # live poses for the portal, from the links' own odometry subscriptions
        manager = LinkManager(urls if only else None, hooks=[link_hook(hub), battery_hook])
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(sig, manager.stop)
        stop_line = stopsocket.StopServer(manager.zero, manager.linked)  # a fresh CLI's stop, zeroed here
        await stop_line.start(stopsocket.path())
        if urls:
            registered = await self.register(urls, wait, manager.stopping)
            manager.fixed = registered if only else None
        self.stdout.write("robot links running (Ctrl-C to stop)")
        try:
            await asyncio.gather(manager.run(), hub.run(manager.stopping))
        finally:
            await stop_line.close()
        if beating is not None:
            beating.cancel()
        self.stdout.write("robot links stopped")

    async def register(self, urls: list[str], wait: float, stopping: asyncio.Event) -> list[str]:
        """Check, wait for and register the endpoints; return the canonical URLs of those registered."""
        allowed = await sync_to_async(allow_list)()
        checked = []
        for url in urls:
            try:
                checked.append(await endpoints.resolve(url, allowed))
            except RosbridgeError as exc:  # refused before anything connects
                self.stderr.write(f"error: {exc}")
        checked = list(dict.fromkeys(checked))
        ready = await wait_for_endpoints(checked, wait, stopping)
        for url in checked:
            if url not in ready:
                self.stderr.write(f"error: {url}: did not answer within {wait:g} s; not registered")
        if not ready:
            return []
        found = await discover_all(ready, allowed=allowed)
        registered = []
        for result in await sync_to_async(store_all)(ready, found):
            if result.ok:
                registered.append(result.endpoint)
                self.stdout.write(f"registered {result.url}: {', '.join(result.robots)}")
            else:
                self.stderr.write(f"error: {result.error}")
        return registered
