"""Django's Redis cache, with one redis.Redis client per connection pool instead of one per call.

Django's RedisCacheClient.get_client builds a new redis.Redis for every cache operation, and redis-py fills a
table of response callbacks in each new client: about 0.4 ms a call on this machine, more than the round trip
itself. The interpreter checks the ontology and fleet versions in the cache on every instruction, the pose hub
and pages read it on every push, so that cost was most of an instruction's interpretation (bench.interpreter_
throughput). A redis.Redis is thread-safe (it takes a connection from its pool per command), so one per pool
serves every thread of the process.
"""

from django.core.cache.backends import redis as django_redis


class RedisCacheClient(django_redis.RedisCacheClient):
    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self._clients: dict[int, object] = {}

    def get_client(self, key=None, *, write=False):
        index = self._get_connection_pool_index(write)
        client = self._clients.get(index)
        if client is None:
            if index not in self._pools:
                self._pools[index] = self._pool_class.from_url(self._servers[index], **self._pool_options)
            client = self._clients[index] = self._client(connection_pool=self._pools[index])
        return client


class RedisCache(django_redis.RedisCache):
    def __init__(self, server, params) -> None:
        super().__init__(server, params)
        self._class = RedisCacheClient
