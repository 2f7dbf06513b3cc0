"""Where the cluster test can run: the skip reason is checked, not assumed."""

from deploy import cluster


def test_a_cluster_needs_root(monkeypatch):
    monkeypatch.setattr(cluster.os, "geteuid", lambda: 1000)
    assert cluster.reason_unavailable() == "network namespaces need root (euid is not 0)"


def test_a_cluster_needs_iproute2(monkeypatch):
    monkeypatch.setattr(cluster.os, "geteuid", lambda: 0)
    monkeypatch.setattr(cluster.shutil, "which", lambda name: None)
    assert cluster.reason_unavailable() == "no `ip` command (iproute2)"


def test_every_host_has_its_own_address_on_the_bridge():
    addresses = [cluster.address(host) for host in cluster.HOSTS]
    assert len(set(addresses)) == len(cluster.HOSTS)
    assert all(a.startswith(cluster.SUBNET + ".") and a != cluster.GATEWAY for a in addresses)
