"""fleet.websocket: uvicorn's WebSocket protocol compressing at zlib level 1, served by every web command."""

import asyncio
import threading
import time

import pytest
import uvicorn
import websockets
from websockets.extensions.permessage_deflate import PerMessageDeflate

from fleet import websocket
from fleet.settings import BASE_DIR
from simworker.testing import bound_socket

TEXT = (
    '{"type":"fleet.poses","rows":[' + ",".join(f"[{n},1.25,-0.5,3.1,0.0,0.3,{n}]" for n in range(300)) + "]}"
)


async def app(scope, receive, send):
    """An ASGI app that accepts a socket and sends it one large text."""
    assert scope["type"] == "websocket"
    await receive()
    await send({"type": "websocket.accept"})
    await send({"type": "websocket.send", "text": TEXT})
    await receive()


@pytest.fixture
def server():
    sock, port = bound_socket()
    config = uvicorn.Config(
        app, host="127.0.0.1", port=port, log_level="warning", lifespan="off", ws=websocket.Protocol
    )
    served = uvicorn.Server(config)
    thread = threading.Thread(target=served.run, kwargs={"sockets": [sock]}, daemon=True)
    thread.start()
    deadline = time.monotonic() + 10
    while not served.started:
        assert time.monotonic() < deadline, "uvicorn did not start"
        time.sleep(0.02)
    yield port, served
    served.should_exit = True
    thread.join(10)


def test_a_browser_offering_compression_gets_it_and_reads_what_was_sent(server):
    port, _served = server

    async def read():
        async with websockets.connect(f"ws://127.0.0.1:{port}/", compression="deflate", max_size=None) as ws:
            text = await asyncio.wait_for(ws.recv(), 5)
            return text, [type(e) for e in ws.protocol.extensions]

    text, extensions = asyncio.run(read())
    assert text == TEXT and extensions == [PerMessageDeflate]  # negotiated as uvicorn's own protocol does


def test_the_protocol_sets_level_one_on_uvicorns_deflate_and_nothing_else():
    config = uvicorn.Config(app, ws=websocket.Protocol)
    config.load()

    async def made():  # a protocol is made on the server's loop
        return websocket.Protocol(config=config, server_state=uvicorn.server.ServerState(), app_state={})

    (factory,) = asyncio.run(made()).conn.available_extensions
    assert factory.compress_settings == {"memLevel": 5, "level": websocket.LEVEL}
    assert (factory.server_max_window_bits, factory.client_max_window_bits) == (12, 12)  # uvicorn's, kept


def test_every_web_server_of_the_repository_serves_it(tmp_path):
    from fleet.run import Setup, programs

    (web,) = [p for p in programs(Setup.from_env({"FLEET_VAR_DIR": str(tmp_path)})) if p.name == "web"]
    assert " ".join(websocket.OPTION) in " ".join(web.command)
    for path in (
        "deploy/systemd/fleet-web.service",
        "deploy/supervisord.conf",
        "deploy/cluster.py",
        "bench/portal.py",
    ):
        text = (BASE_DIR / path).read_text()
        assert "fleet.websocket:Protocol" in text or "websocket.OPTION" in text, path
