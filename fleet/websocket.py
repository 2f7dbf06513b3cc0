"""uvicorn's WebSocket protocol (websockets' sans-I/O one), its permessage-deflate at zlib level 1.

Browsers offer permessage-deflate and uvicorn takes it: every socket compresses each message it is sent, with a
compressor of its own. A dashboard is sent a tick of every robot's pose ten times a second, so that compressor is
most of what one more dashboard costs a web process (docs/scale.md, "The cost of a robot"). At zlib's default
level (6) a 100-robot tick took twice level 1's time for 13 % fewer bytes (1.4 against 1.6 kB a tick).

Served by giving uvicorn `--ws fleet.websocket:Protocol` (OPTION; every command of this repository that starts a
web server does). Only the level changes: the window sizes and the negotiation stay uvicorn's.

Tried and dropped (2026-11-28): server_no_context_takeover with a tick compressed once for every socket. One
host's bench gave the web 0.65x per dashboard, but on the cluster at 100 robots the web's CPU was no lower and the
staleness p99 worse in four runs of four (docs/scale.md, "night").
"""

from __future__ import annotations

from uvicorn.protocols.websockets.websockets_sansio_impl import WebSocketsSansIOProtocol
from websockets.extensions.permessage_deflate import ServerPerMessageDeflateFactory

LEVEL = 1
OPTION = ["--ws", "fleet.websocket:Protocol"]  # uvicorn's command-line option that serves this protocol


class Protocol(WebSocketsSansIOProtocol):
    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        for factory in self.conn.available_extensions:
            if isinstance(factory, ServerPerMessageDeflateFactory):
                factory.compress_settings = {**(factory.compress_settings or {}), "level": LEVEL}
