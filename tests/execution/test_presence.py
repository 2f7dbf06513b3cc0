"""A lock holder's presence (execution.coordination.present): Redis drops a process's subscription to its presence
channel the moment its socket closes, so a killed executor is seen gone without waiting for its locks to lapse; the
watchdog takes a holder missing at two looks GONE_S apart as gone, not one missing once (a reconnect)."""

import os
import signal
import socket
import subprocess
import sys
import time

import pytest
from django.conf import settings

from execution import coordination, watchdog
from tests.execution.helpers import wait_for

pytestmark = [pytest.mark.timeout(60)]

SUBSCRIBER = """
import os, sys, time, redis
pubsub = redis.Redis.from_url(sys.argv[1]).pubsub()
pubsub.subscribe(f"{sys.argv[2]}:{os.getpid()}")  # its presence channel, as coordination.presence_channel names it
pubsub.get_message(timeout=5)  # the confirmation: subscribed
print("ready", flush=True)
time.sleep(60)
"""


@pytest.fixture
def holder():
    """A process of its own subscribed to its presence channel, as an executor's board is: (process, Popen)."""
    host = socket.gethostname()
    prefix = coordination.presence_channel(host)
    proc = subprocess.Popen(
        [sys.executable, "-c", SUBSCRIBER, settings.REDIS_URL, prefix], stdout=subprocess.PIPE, text=True
    )
    try:
        assert proc.stdout.readline().strip() == "ready"
        yield f"{host}:{proc.pid}", proc
    finally:
        proc.kill()
        proc.wait()


def test_a_process_is_present_while_subscribed_and_not_once_killed(holder):
    process, proc = holder
    assert coordination.present([process]) == {process: True}
    os.kill(proc.pid, signal.SIGKILL)
    wait_for(lambda: coordination.present([process]) == {process: False}, 2, "the subscription dropped")


def test_a_process_missing_at_one_look_is_not_gone_until_missing_gone_s_later(holder):
    here, _ = holder
    missing = f"{here.split(':')[0]}:{2**22 + 7}"  # above the default pid_max: no process has it
    absences = watchdog._Absences()
    assert absences.gone({here, missing}) == set()  # missing once: maybe reconnecting
    time.sleep(watchdog.GONE_S)
    assert absences.gone({here, missing}) == {missing}  # still missing: gone; the present one never is


def test_a_lock_token_names_its_process():
    token = coordination.new_token()
    assert coordination.holder_process(token) == coordination.process_name()
    assert coordination.process_name().endswith(f":{os.getpid()}")
    assert coordination.holder_process("someone else") is None  # not made by new_token: its lock's lapse only


def test_a_look_without_the_process_forgets_its_absence():
    """Missing, then no longer holding a lock (a look without it), then holding one again and missing once: that
    is its first look missing, not a second one."""
    missing = f"{socket.gethostname()}:{2**22 + 9}"
    absences = watchdog._Absences()
    assert absences.gone({missing}) == set()
    time.sleep(watchdog.GONE_S)
    assert absences.gone(set()) == set()  # none held: nothing asked of Redis, and the absence forgotten
    assert absences.gone({missing}) == set()
