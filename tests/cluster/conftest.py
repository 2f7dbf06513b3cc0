"""One multi-host cluster (deploy/cluster.py: network namespaces on a private bridge) for the module."""

from __future__ import annotations

import os

import pytest

from deploy.cluster import Cluster, down, reason_unavailable

ROBOTS_PER_SHARD = int(os.environ.get("FLEET_CLUSTER_ROBOTS", "10"))


@pytest.fixture(scope="module")
def cluster():
    """The cluster, up; taken down (every process, namespace, veth and the bridge) however the module ends.

    Skipped only where namespaces cannot be made: not root, no `ip`, no PostgreSQL or Redis server binaries
    (the reason is `deploy.cluster.reason_unavailable()`'s)."""
    reason = reason_unavailable()
    if reason:
        pytest.skip(f"multi-host cluster not run: {reason}")
    # 1 m apart, not the world's packed 0.45 m grid: the walk-through judges hosts, not traffic out of a crowd
    # (where robots stopped mid-way may take longer than its bounds to thread out; bench/coordination.py measures that)
    running = Cluster(robots_per_shard=ROBOTS_PER_SHARD, spacing=1.0)
    try:
        running.up(say=lambda line: print(f"cluster: {line}"))
        yield running
    finally:
        down(running.root, say=lambda line: print(f"cluster: {line}"))
