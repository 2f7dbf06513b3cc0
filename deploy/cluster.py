"""A multi-host fleet on one machine: network namespaces as hosts on a private bridge (issue 19).

    sudo .venv/bin/python -m deploy.cluster up [--robots-per-shard 25]    (or: make cluster-up)
    sudo .venv/bin/python -m deploy.cluster down                           (or: make cluster-down)
    sudo .venv/bin/python -m deploy.cluster status

Hosts (each a network namespace with its own hostname, one veth on the bridge `fleetbr0`, 10.77.0.0/24):

    db     10.77.0.10  PostgreSQL (a cluster of its own, made with initdb under the state folder) and Redis
    web1   10.77.0.11  uvicorn, the ASGI app, port 8000
    web2   10.77.0.12  the same
    exec1  10.77.0.21  the robots' executors (`manage.py executor`), the Celery `instructions` worker (recordings,
                       experiment runs) and the `control,registration` one
    exec2  10.77.0.22  the same
    sim1   10.77.0.31  a simulator shard: the paper world's `extra` endpoint, its first slice of robots, port 9094
    sim2   10.77.0.32  the next slice of robots, same port on its own address
    links  10.77.0.40  the robot links (`robotlinks`) and the scheduler (time slots, the executors' watchdog)

Every process gets its settings from the environment only, as in production: `cluster.env` in the state folder
(DATABASE_URL, REDIS_URL, SECRET_KEY, ALLOWED_HOSTS, FLEET_ROBOT_ALLOWED_NETWORKS, ...; the one file a real
deployment keeps as /etc/fleet/fleet.env). The machine's own environment (a test run's REDIS_URL...) is not passed
on. All traffic stays on the bridge; the machine itself reaches the hosts at their addresses (the bridge has
10.77.0.1). `down` kills every process in the namespaces (found by namespace, so a crashed `up` is cleaned too),
deletes the namespaces (their veths go with them) and the bridge, and removes the state folder but its logs;
it is idempotent. Needs root and iproute2 (`ip netns`); `reason_unavailable()` says why not when it cannot run.
One cluster per machine: `up` first takes down whatever cluster is there (the test's, the benchmark's).
"""

from __future__ import annotations

import argparse
import contextlib
import glob
import json
import os
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import time
import urllib.request
from dataclasses import dataclass, field
from pathlib import Path

BASE_DIR = Path(__file__).resolve().parent.parent
BRIDGE = "fleetbr0"
NS_PREFIX = "fleet-"
SUBNET = "10.77.0"
GATEWAY = f"{SUBNET}.1"
HOSTS = {"db": 10, "web1": 11, "web2": 12, "exec1": 21, "exec2": 22, "sim1": 31, "sim2": 32, "links": 40}
WEB_PORT = 8000
SIM_PORT_BASE = 9090
SIM_ENDPOINT = "extra"  # the paper world's endpoint of namespaced robots: port offset 4
SIM_PORT = SIM_PORT_BASE + 4
ADMIN_PASSWORD = "cluster-admin"
DEFAULT_DIR = Path(os.environ.get("FLEET_CLUSTER_DIR", "/tmp/fleet-cluster"))
KEPT_ENV = ("PATH", "LANG", "LC_ALL", "HOME", "TERM")
REDIS_OPTIONS = ["--save", "", "--appendonly", "no", "--protected-mode", "no", "--dir", "/tmp"]


def address(host: str) -> str:
    return f"{SUBNET}.{HOSTS[host]}"


def namespace(host: str) -> str:
    return NS_PREFIX + host


def reason_unavailable() -> str | None:
    """Why a cluster cannot be made here (None: it can): root and iproute2's `ip netns` are needed."""
    if os.geteuid() != 0:
        return "network namespaces need root (euid is not 0)"
    if shutil.which("ip") is None:
        return "no `ip` command (iproute2)"
    probe = subprocess.run(["ip", "netns", "list"], capture_output=True, text=True)
    if probe.returncode:
        return f"`ip netns list` failed: {probe.stderr.strip()}"
    if not glob.glob("/usr/lib/postgresql/*/bin/initdb"):
        return "no PostgreSQL server binaries under /usr/lib/postgresql/*/bin"
    if shutil.which("redis-server") is None:
        return "no redis-server"
    return None


def sh(*argv: str, check: bool = True) -> subprocess.CompletedProcess:
    return subprocess.run(argv, capture_output=True, text=True, check=check)


def pg_bin(name: str) -> str:
    return sorted(glob.glob(f"/usr/lib/postgresql/*/bin/{name}"))[-1]


@dataclass
class Role:
    """One process of a host: its name and its command (run in the host's namespace, under its hostname)."""

    host: str
    name: str
    argv: list[str]
    user: str | None = None


@dataclass
class Cluster:
    root: Path = DEFAULT_DIR
    robots_per_shard: int = 10
    python: str = sys.executable
    executors: int = 1  # executor processes on each exec host
    spacing: float | None = None  # metres between the simulated robots (the paper world's 0.45 fits 532)
    pids: dict[str, int] = field(default_factory=dict)

    # ----- layout -----
    @property
    def log_dir(self) -> Path:
        return self.root / "log"

    @property
    def env_file(self) -> Path:
        return self.root / "cluster.env"

    def url(self, host: str = "web1") -> str:
        return f"http://{address(host)}:{WEB_PORT}/"

    def sim_url(self, host: str) -> str:
        return f"ws://{address(host)}:{SIM_PORT}"

    def shard_robots(self, host: str) -> list[str]:
        """The names of the robots a shard serves (the paper world's extra robots start at robot5)."""
        shard = ["sim1", "sim2"].index(host)
        first = 5 + shard * self.robots_per_shard
        return [f"robot{first + i}" for i in range(self.robots_per_shard)]

    def settings(self) -> dict[str, str]:
        """The environment every process gets: the production variables of deploy/fleet.env.example."""
        if self.env_file.exists():
            return dict(line.split("=", 1) for line in self.env_file.read_text().splitlines() if "=" in line)
        webs = [address("web1"), address("web2"), GATEWAY]
        values = {
            "DATABASE_URL": f"postgres://postgres@{address('db')}:5432/fleet",
            "REDIS_URL": f"redis://{address('db')}:6379/0",
            "SECRET_KEY": secrets.token_urlsafe(50),
            "ALLOWED_HOSTS": ",".join(webs),
            "FLEET_ROBOT_ALLOWED_NETWORKS": f"{SUBNET}.0/24",
            "FLEET_ADMIN_PASSWORD": ADMIN_PASSWORD,
            "FLEET_WORLD": "paper",
            # a shard is one endpoint of hundreds of robots: its discovery takes longer than the default 15 s
            "FLEET_DISCOVERY_TIMEOUT_S": "300",
        }
        self.env_file.write_text("".join(f"{k}={v}\n" for k, v in values.items()))
        return values

    def env(self, host: str) -> dict[str, str]:
        base = {k: os.environ[k] for k in KEPT_ENV if k in os.environ}
        var = self.root / "var" / host
        var.mkdir(parents=True, exist_ok=True)
        return {**base, **self.settings(), "FLEET_VAR_DIR": str(var), "PYTHONUNBUFFERED": "1"}

    def roles(self) -> list[Role]:
        """Every process of the cluster, host by host (the database's first)."""
        py, manage = self.python, [self.python, "manage.py"]
        celery = [py, "-m", "celery", "-A", "fleet", "-q", "worker", "-l", "warning"]
        pg_data = str(self.root / "pg")
        listed = [
            Role(
                "db",
                "postgres",
                [pg_bin("postgres"), "-D", pg_data, "-k", pg_data, "-c", f"listen_addresses={address('db')}"],
                user="postgres",
            ),
            Role("db", "redis", ["redis-server", "--bind", address("db"), "--port", "6379", *REDIS_OPTIONS]),
        ]
        for host in ("web1", "web2"):
            web = ["--host", address(host), "--port", str(WEB_PORT), "--log-level", "warning"]
            listed.append(
                Role(
                    host,
                    "web",
                    [
                        py,
                        "-m",
                        "uvicorn",
                        "fleet.asgi:application",
                        *web,
                        "--no-proxy-headers",
                        "--ws",
                        "fleet.websocket:Protocol",
                    ],
                )
            )
        for host in ("exec1", "exec2"):
            for n in range(1, self.executors + 1):
                listed.append(Role(host, f"executor-{n}", [*manage, "executor"]))
            tasks = ["-n", f"instructions@{host}", "-Q", "instructions", "-P", "threads", "-c", "4"]
            listed.append(Role(host, "worker", [*celery, *tasks]))  # recordings, experiment runs
            listed.append(
                Role(
                    host,
                    "control",
                    [*celery, "-n", f"control@{host}", "-Q", "control,registration", "-c", "1"],
                )
            )
        for shard, host in enumerate(("sim1", "sim2")):
            sim = ["--world", "paper", "--endpoints", SIM_ENDPOINT, "--extra", str(self.robots_per_shard)]
            sim += ["--extra-skip", str(shard * self.robots_per_shard), "--host", address(host)]
            sim += ["--extra-spacing", str(self.spacing)] if self.spacing else []
            listed.append(Role(host, "sim", [*manage, "simworker", *sim, "--port-base", str(SIM_PORT_BASE)]))
        listed.append(Role("links", "links", [*manage, "robotlinks"]))
        listed.append(Role("links", "scheduler", [*manage, "scheduler"]))
        return listed

    # ----- the network -----
    def make_network(self) -> None:
        sh("ip", "link", "add", BRIDGE, "type", "bridge")
        sh("ip", "addr", "add", f"{GATEWAY}/24", "dev", BRIDGE)
        sh("ip", "link", "set", BRIDGE, "up")
        for host in HOSTS:
            ns, outside = namespace(host), f"fc-{host}"
            sh("ip", "netns", "add", ns)
            sh("ip", "link", "add", outside, "type", "veth", "peer", "name", "eth0", "netns", ns)
            sh("ip", "link", "set", outside, "master", BRIDGE)
            sh("ip", "link", "set", outside, "up")
            sh("ip", "-n", ns, "addr", "add", f"{address(host)}/24", "dev", "eth0")
            sh("ip", "-n", ns, "link", "set", "eth0", "up")
            sh("ip", "-n", ns, "link", "set", "lo", "up")

    # ----- processes -----
    def start(self, role: Role) -> int:
        """Start one role's process in its host's namespace, with the host's name; its pid."""
        self.log_dir.mkdir(parents=True, exist_ok=True)
        log = open(self.log_dir / f"{role.host}-{role.name}.log", "ab")  # noqa: SIM115 - the child keeps it
        argv = ["runuser", "-u", role.user, "--", *role.argv] if role.user else role.argv
        named = ["unshare", "--uts", "--", "sh", "-c", 'hostname "$0" && exec "$@"', role.host, *argv]
        process = subprocess.Popen(
            ["ip", "netns", "exec", namespace(role.host), *named],
            cwd=BASE_DIR,
            env=self.env(role.host),
            stdout=log,
            stderr=subprocess.STDOUT,
            stdin=subprocess.DEVNULL,
            start_new_session=True,
        )
        log.close()
        self.pids[f"{role.host}/{role.name}"] = process.pid
        return process.pid

    def start_host(self, host: str) -> None:
        for role in self.roles():
            if role.host == host:
                self.start(role)

    def kill_host(self, host: str) -> list[int]:
        """kill -9 every process of a host (all of its namespace's), as a lost machine; their pids."""
        return kill_all(host_pids(host))

    def run_in(self, host: str, *argv: str, timeout: float = 300) -> subprocess.CompletedProcess:
        """A one-off command on a host (migrate, setup_demo), as the host's processes run."""
        return subprocess.run(
            ["ip", "netns", "exec", namespace(host), *argv],
            cwd=BASE_DIR,
            env=self.env(host),
            capture_output=True,
            text=True,
            timeout=timeout,
        )

    # ----- up -----
    def up(self, say=print) -> None:
        down(self.root, say=lambda _line: None)
        self.root.mkdir(parents=True, exist_ok=True)
        self.settings()
        self.make_network()
        say(f"network: bridge {BRIDGE} {GATEWAY}/24, hosts {', '.join(f'{h} {address(h)}' for h in HOSTS)}")
        self.up_database()
        say(f"db: PostgreSQL {address('db')}:5432, Redis {address('db')}:6379")
        for step in (["migrate", "--noinput", "-v", "0"], ["setup_demo"]):
            done = self.run_in("web1", self.python, "manage.py", *step)
            if done.returncode:
                raise RuntimeError(f"manage.py {step[0]} failed:\n{done.stdout}{done.stderr}")
        for host in ("web1", "web2", "exec1", "exec2", "sim1", "sim2", "links"):
            self.start_host(host)
        self.save()
        for host in ("web1", "web2"):
            wait_for(lambda h=host: answers(f"{self.url(h)}login/"), 120, f"{host} answering")
        say(f"web: {self.url('web1')} and {self.url('web2')} (admin / {ADMIN_PASSWORD})")
        say(
            f"simulator shards: {self.sim_url('sim1')} and {self.sim_url('sim2')}, {self.robots_per_shard} robots each"
        )
        say(f"logs: {self.log_dir}; `python -m deploy.cluster down` removes it all")

    def up_database(self) -> None:
        data = self.root / "pg"
        data.mkdir()
        shutil.chown(data, "postgres", "postgres")
        initdb = [pg_bin("initdb"), "-D", str(data), "-A", "trust", "-U", "postgres", "--no-sync"]
        sh("runuser", "-u", "postgres", "--", *initdb)
        config = "fsync = off\nsynchronous_commit = off\nmax_connections = 400\nshared_buffers = 64MB\n"
        with open(data / "postgresql.conf", "a") as conf:
            conf.write(config)
        with open(data / "pg_hba.conf", "a") as hba:
            hba.write(f"host all all {SUBNET}.0/24 trust\n")
        self.start_host("db")
        wait_for(
            lambda: port_open(address("db"), 5432) and port_open(address("db"), 6379), 60, "db answering"
        )
        create = [pg_bin("createdb"), "-h", address("db"), "-U", "postgres", "fleet"]
        wait_for(lambda: sh(*create, check=False).returncode == 0, 30, "database created")

    def save(self) -> None:
        (self.root / "cluster.json").write_text(
            json.dumps(
                {"robots_per_shard": self.robots_per_shard, "spacing": self.spacing, "pids": self.pids},
                indent=1,
            )
        )

    @classmethod
    def load(cls, root: Path = DEFAULT_DIR) -> Cluster:
        state = json.loads((root / "cluster.json").read_text())
        return cls(
            root=root,
            robots_per_shard=state["robots_per_shard"],
            spacing=state["spacing"],
            pids=state["pids"],
        )


# ----- down -----
def namespaces() -> list[str]:
    listed = sh("ip", "netns", "list", check=False).stdout.split()
    return [name for name in listed if name.startswith(NS_PREFIX)]


def host_pids(host: str) -> list[int]:
    return [int(pid) for pid in sh("ip", "netns", "pids", namespace(host), check=False).stdout.split()]


def alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as stat:
            return stat.read().rsplit(")", 1)[1].split()[0] != "Z"
    except (FileNotFoundError, ProcessLookupError, IndexError):
        return False


def kill_all(pids: list[int], wait_s: float = 10.0) -> list[int]:
    """kill -9 each process and wait (bounded) until none is alive; the pids."""
    for pid in pids:
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGKILL)
    deadline = time.monotonic() + wait_s
    while time.monotonic() < deadline and any(alive(pid) for pid in pids):
        time.sleep(0.05)
    return pids


def down(root: Path = DEFAULT_DIR, say=print) -> None:
    """Remove every process, namespace, veth and the bridge a cluster made; keep only its logs. Idempotent."""
    found = namespaces()
    pids = kill_all(
        [int(p) for ns in found for p in sh("ip", "netns", "pids", ns, check=False).stdout.split()]
    )
    for ns in found:
        sh("ip", "netns", "del", ns, check=False)
    for host in HOSTS:  # a veth left by an `up` that died between its two ends
        sh("ip", "link", "del", f"fc-{host}", check=False)
    sh("ip", "link", "del", BRIDGE, check=False)
    if root.exists():
        for child in root.iterdir():
            if child.name != "log":
                shutil.rmtree(child) if child.is_dir() else child.unlink()
    say(f"cluster down: {len(pids)} processes killed, {len(found)} namespaces and the bridge removed")


# ----- waiting -----
def port_open(host: str, port: int) -> bool:
    try:
        with socket.create_connection((host, port), timeout=1):
            return True
    except OSError:
        return False


def answers(url: str) -> bool:
    try:
        with urllib.request.urlopen(url, timeout=3) as response:
            return response.status == 200
    except OSError:
        return False


def wait_for(condition, timeout: float, what: str) -> float:
    start = time.monotonic()
    while time.monotonic() - start < timeout:
        if condition():
            return time.monotonic() - start
        time.sleep(0.2)
    raise TimeoutError(f"not within {timeout:g} s: {what}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m deploy.cluster", description=__doc__.split("\n")[0])
    parser.add_argument("command", choices=["up", "down", "status"])
    parser.add_argument("--robots-per-shard", type=int, default=10)
    parser.add_argument(
        "--spacing", type=float, help="metres between robots (0.3 fits 1,239 in the paper world)"
    )
    parser.add_argument("--dir", type=Path, default=DEFAULT_DIR, help="state folder (FLEET_CLUSTER_DIR)")
    args = parser.parse_args(argv)
    if args.command == "down":
        if os.geteuid() != 0:
            print("cluster: down needs root", file=sys.stderr)
            return 1
        down(args.dir)
        return 0
    if args.command == "status":
        for ns in namespaces():
            print(ns, "pids:", " ".join(sh("ip", "netns", "pids", ns, check=False).stdout.split()) or "-")
        return 0
    reason = reason_unavailable()
    if reason:
        print(f"cluster: cannot run here: {reason}", file=sys.stderr)
        return 1
    cluster = Cluster(root=args.dir, robots_per_shard=args.robots_per_shard, spacing=args.spacing)
    try:
        cluster.up()
    except (RuntimeError, TimeoutError, subprocess.CalledProcessError) as exc:
        detail = getattr(exc, "stderr", "") or ""
        print(f"cluster: up failed: {exc} {detail}\nlogs in {cluster.log_dir}; cleaning up", file=sys.stderr)
        down(args.dir)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
