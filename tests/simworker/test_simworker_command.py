"""`manage.py simworker` prints one line per endpoint when ready, needs no database, stops on SIGTERM/SIGINT."""

import os
import signal
import socket
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
pytestmark = pytest.mark.timeout(60)


def free_port_base(span: int = 7) -> int:
    """Find `span` consecutive free TCP ports on loopback."""
    for base in range(21000, 40000, 97):
        socks = []
        try:
            for offset in range(span):
                s = socket.socket()
                socks.append(s)
                s.bind(("127.0.0.1", base + offset))
            return base
        except OSError:
            continue
        finally:
            for s in socks:
                s.close()
    raise RuntimeError("no free port range")


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_command_serves_every_endpoint_and_stops_cleanly(sig):
    base = free_port_base()
    env = {**os.environ, "DATABASE_URL": "postgres://nobody@127.0.0.1:1/unreachable", "PYTHONUNBUFFERED": "1"}
    proc = subprocess.Popen(
        [
            sys.executable,
            "manage.py",
            "simworker",
            "--world",
            "paper",
            "--port-base",
            str(base),
            "--extra",
            "2",
        ],
        cwd=ROOT,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        lines = [proc.stdout.readline().strip() for _ in range(7)]
        assert lines[1] == f"simworker: turtlebot ready at ws://127.0.0.1:{base + 1}"
        assert f"simworker: extra ready at ws://127.0.0.1:{base + 4}" in lines
        assert {line.split()[1] for line in lines} == {
            "robots",
            "turtlebot",
            "husky",
            "tiago",
            "extra",
            "spot",
            "tb3_nav2",
        }
        with socket.create_connection(("127.0.0.1", base + 2), timeout=5):
            pass
        proc.send_signal(sig)
        out, err = proc.communicate(timeout=15)
    finally:
        proc.kill()
    assert proc.returncode == 0, err[-2000:]
    assert "stopped after" in out


def test_command_rejects_a_bad_world():
    proc = subprocess.run(
        [sys.executable, "manage.py", "simworker", "--world", "no_such_world"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=30,
        check=False,
    )
    assert proc.returncode != 0
    assert "no_such_world" in proc.stderr and "cannot read world" in proc.stderr
