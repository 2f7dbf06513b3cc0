"""Django's Redis cache, with one redis.Redis client per connection pool instead of one per call.

Django's RedisCacheClient.get_client builds a new redis.Redis for every cache operation, and redis-py fills a
table of response callbacks in each new client: about 0.4 ms a call on this machine, more than the round trip
itself. The interpreter checks the ontology and fleet versions in the cache on every instruction, the pose hub
and pages read it on every push, so that cost was most of an instruction's interpretation (bench.interpreter_
throughput). A redis.Redis is thread-safe (it takes a connection from its pool per command), so one per pool
serves every thread of the process.

set_many writes each key with its expiry in one SET (PX), pipelined without a transaction, where Django's sends
an MSET, then an EXPIRE per key, inside MULTI/EXEC: the pose hub stores every robot's pose ten times a second,
and half of those commands were the EXPIREs. (Each key is still written whole; a reader sees the old value or
the new, never a key without its expiry.)
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

    def set_many(self, data, timeout):
        if timeout == 0:  # as Django's set: a key that expires at once is deleted
            self.delete_many(list(data))
            return
        pipeline = self.get_client(None, write=True).pipeline(transaction=False)
        for key, value in data.items():
            pipeline.set(key, self._serializer.dumps(value), ex=timeout)
        pipeline.execute()


class RedisCache(django_redis.RedisCache):
    def __init__(self, server, params) -> None:
        super().__init__(server, params)
        self._class = RedisCacheClient
