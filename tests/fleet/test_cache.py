"""fleet.cache: set_many writes each key with its expiry in one SET, on the real Redis."""

import pytest
from django.core.cache import cache


@pytest.fixture
def keys():
    names = [f"test-cache-{n}" for n in range(3)]
    yield names
    cache.delete_many(names)


def test_set_many_stores_every_value_with_its_expiry(keys):
    cache.set_many({key: {"id": n, "x": 0.5 * n} for n, key in enumerate(keys)}, timeout=60)
    assert cache.get_many(keys) == {key: {"id": n, "x": 0.5 * n} for n, key in enumerate(keys)}
    client = cache._cache.get_client(write=True)
    ttls = [client.ttl(cache.make_key(key)) for key in keys]
    assert all(55 <= ttl <= 60 for ttl in ttls), ttls


def test_set_many_without_a_timeout_keeps_the_keys_and_with_zero_deletes_them(keys):
    cache.set_many(dict.fromkeys(keys, 1), timeout=None)
    client = cache._cache.get_client(write=True)
    assert [client.ttl(cache.make_key(key)) for key in keys] == [-1, -1, -1]  # no expiry
    cache.set_many(dict.fromkeys(keys, 2), timeout=0)
    assert cache.get_many(keys) == {}


def test_a_hash_keeps_its_fields_under_one_key_that_expires_as_a_whole():
    key = "test-cache-hash"
    try:
        cache.hash_set(key, {1: {"id": 1, "x": 0.5}, 2: {"id": 2, "x": 1.5}}, timeout=60)
        cache.hash_set(key, {2: {"id": 2, "x": 2.5}}, timeout=60)  # one field written again, the other kept
        assert cache.hash_get(key, [1, 2, 3]) == {1: {"id": 1, "x": 0.5}, 2: {"id": 2, "x": 2.5}}
        client = cache._cache.get_client(write=True)
        assert client.hlen(cache.make_key(key)) == 2
        assert 55 <= client.ttl(cache.make_key(key)) <= 60
        cache.hash_delete(key, [1])
        assert cache.hash_get(key, [1, 2]) == {2: {"id": 2, "x": 2.5}}
        assert cache.hash_get(key, []) == {}
    finally:
        cache.delete(key)
