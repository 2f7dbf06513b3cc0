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

The hash methods keep many small values under one key, one field each (robots.poses: every robot's last pose), so
that a tick of a hundred poses is one HSET, and a read of them one HMGET, where a key per value cost a SET and its
reply each: the pose store was a third of the links process's time at 100 robots (py-spy, bench.cost). A hash
expires as a whole: a field's own age is its owner's business.
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

    def hash_set(self, key, mapping: dict, timeout) -> None:
        pipeline = self.get_client(None, write=True).pipeline(transaction=False)
        pipeline.hset(key, mapping={field: self._serializer.dumps(value) for field, value in mapping.items()})
        pipeline.expire(key, timeout)
        pipeline.execute()

    def hash_get(self, key, fields: list) -> dict:
        values = self.get_client(key).hmget(key, fields) if fields else []
        return {
            field: self._serializer.loads(value)
            for field, value in zip(fields, values, strict=True)
            if value is not None
        }

    def hash_delete(self, key, fields: list) -> None:
        if fields:
            self.get_client(key, write=True).hdel(key, *fields)


class RedisCache(django_redis.RedisCache):
    """Django's Redis cache, and values kept as fields of one hash (hash_set, hash_get, hash_delete)."""

    def __init__(self, server, params) -> None:
        super().__init__(server, params)
        self._class = RedisCacheClient

    def hash_set(self, key: str, mapping: dict, timeout: int) -> None:
        """Write these fields of the hash at key (their values pickled, as the cache's), which then expires in
        timeout seconds unless written again."""
        self._cache.hash_set(self.make_and_validate_key(key), mapping, timeout)

    def hash_get(self, key: str, fields) -> dict:
        """{field: value} of those fields of the hash at key that are there."""
        return self._cache.hash_get(self.make_and_validate_key(key), list(fields))

    def hash_delete(self, key: str, fields) -> None:
        self._cache.hash_delete(self.make_and_validate_key(key), list(fields))
