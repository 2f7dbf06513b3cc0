"""The Celery app: queues per concern (instructions, control, registration, sim).

Its Redis transport says a closed channel's failures as the connection errors they are (see RedisChannel), so a
worker that loses Redis in the middle of a task reconnects instead of exiting.
"""

import os

import redis
from celery import Celery
from celery.signals import worker_init, worker_process_init
from kombu import transport
from kombu.transport import redis as kombu_redis

from fleetcore import heartbeat

os.environ.setdefault("DJANGO_SETTINGS_MODULE", "fleet.settings")


class RedisChannel(kombu_redis.Channel):
    """kombu's Redis channel, whose calls after its connection was collected raise ConnectionError.

    When Redis goes away, Celery's consumer collects the broken connection (which detaches the channel from its
    transport) and then closes it; closing restores the unacknowledged messages of the tasks still running, and a
    task that finishes during or after the outage acknowledges on that same channel. Both reach
    `_connparams`, which read `self.connection.client.hostname` on the detached transport: AttributeError, which
    Celery calls an "Unrecoverable error" and exits on (celery/kombu 5.7.0). As a ConnectionError, Celery logs it
    and reconnects; the message stays in Redis's unacknowledged set and is delivered again after the visibility
    timeout (settings.CELERY_BROKER_TRANSPORT_OPTIONS), where the task finds its own claims.
    """

    def _connparams(self, asynchronous=False):
        if self.connection is None or self.connection.client is None:
            raise redis.exceptions.ConnectionError("this channel's broker connection was closed")
        return super()._connparams(asynchronous=asynchronous)


class RedisTransport(kombu_redis.Transport):
    """kombu's Redis transport with RedisChannel."""

    Channel = RedisChannel


# The broker URL names the transport by its scheme (redis://, rediss://, redis+socket://), so ours takes its alias;
# set before any connection is made (kombu caches the class per alias).
transport.TRANSPORT_ALIASES.update(redis=f"{__name__}:RedisTransport", rediss=f"{__name__}:RedisTransport")

app = Celery("fleet")
app.config_from_object("django.conf:settings", namespace="CELERY")
app.autodiscover_tasks()


@worker_process_init.connect
def load_heavy_state(**_kwargs):
    """Load the ontology once per worker process, never at import time."""
    # Deferred: fleet/__init__.py imports this module before the app registry is ready (the service's models).
    from interpreter.service import warm_up

    warm_up()


@worker_init.connect
def start_heartbeat(**_kwargs):
    """The worker's heartbeat, from a thread of its main process: a stopped or frozen worker is seen as hung, not
    one whose consumer waits for its broker (fleet/hangwatch.py would otherwise restart every worker during a
    Redis outage, and their executors with them)."""
    beat = heartbeat.from_env()
    if beat is not None:
        beat.start_thread()
