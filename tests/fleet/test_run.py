"""`make run`: its last words (the URL and the login, once the portal answers) and what it supervises, how."""

import configparser
import io
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

from supervisor.options import ServerOptions

from fleet.run import BASE_DIR, Setup, announcement, programs
from fleet.supervision import (
    LOG_BACKUPS,
    LOG_BYTES,
    START_RETRIES,
    Layout,
    LogRelay,
    render_config,
    supervisor_line,
)
from simworker.testing import free_port


class _Portal(BaseHTTPRequestHandler):
    def do_GET(self):
        self.send_response(200 if self.path == "/login/" else 404)
        self.end_headers()

    def log_message(self, *args):
        pass


def test_the_url_and_login_come_once_the_portal_answers():
    server = ThreadingHTTPServer(("127.0.0.1", 0), _Portal)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    try:
        url = f"http://127.0.0.1:{server.server_address[1]}/"
        said = announcement(url, "login: admin / secret", timeout=5)
    finally:
        server.shutdown()
        server.server_close()
    assert f"Fleet portal ready: {url}" in said and "login: admin / secret" in said


def test_a_portal_that_never_answers_is_said_too():
    url = f"http://127.0.0.1:{free_port()}/"
    said = announcement(url, "login: admin / secret", timeout=1)
    assert f"did not answer at {url} within 1 s" in said and "secret" not in said


# ----- what `make run` supervises, and how -----


def _setup(tmp_path, redis_url=None) -> Setup:
    return Setup(port=8123, sim_port_base=9100, var_dir=tmp_path, world="paper", redis_url=redis_url)


def _parsed(tmp_path, setup: Setup) -> dict:
    """The configuration as supervisord itself reads it: group name → its programs' configs."""
    layout = Layout(tmp_path)
    layout.log_dir.mkdir(exist_ok=True)
    layout.config.write_text(render_config(programs(setup), layout, BASE_DIR))
    options = ServerOptions()
    options.realize(args=["-c", str(layout.config)])
    return {group.name: group for group in options.process_group_configs}


def test_the_embedded_redis_starts_with_the_supervisor_and_before_the_rest(tmp_path):
    groups = _parsed(tmp_path, _setup(tmp_path))
    (redis,) = groups["redis"].process_configs
    assert redis.autostart and groups["redis"].priority < groups["fleet"].priority
    assert redis.command.endswith(f"fleet.embedded_redis serve --socket {tmp_path / 'redis.sock'}")
    assert f"--lock {tmp_path / 'proc' / 'redis.lock'}" in redis.command  # one Redis per var folder
    assert not any(program.autostart for program in groups["fleet"].process_configs)  # after the migration


def test_with_redis_url_set_no_embedded_redis_runs(tmp_path):
    groups = _parsed(tmp_path, _setup(tmp_path, redis_url="redis://127.0.0.1:6379/3"))
    assert set(groups) == {"fleet"}
    assert _setup(tmp_path, "redis://127.0.0.1:6379/3").env()["REDIS_URL"] == "redis://127.0.0.1:6379/3"


def test_every_process_is_restarted_with_backoff_and_reads_its_ports_from_the_setup(tmp_path):
    programs_by_name = {p.name: p for p in _parsed(tmp_path, _setup(tmp_path))["fleet"].process_configs}
    assert set(programs_by_name) == {
        *("web", "executor-1", "worker", "control", "sim", "links", "scheduler", "hangwatch")
    }
    for program in programs_by_name.values():
        assert program.autorestart and program.startretries == START_RETRIES
        assert program.stdout_logfile == str(tmp_path / "log" / f"{program.name}.log")
        # bounded logs (Django's go to these too); each process dies with the supervisor (fleet/procwrap.py)
        assert program.stdout_logfile_maxbytes == LOG_BYTES and program.stdout_logfile_backups == LOG_BACKUPS
        assert f"procwrap.py --parent-pidfile {tmp_path / 'supervisord.pid'}" in program.command
    for name in ("links", "scheduler", "hangwatch"):  # one per var folder, always
        assert f"--lock {tmp_path / 'proc' / name}.lock" in programs_by_name[name].command
    for name in (
        "web",
        "executor-1",
        "worker",
        "control",
        "sim",
        "links",
        "scheduler",
    ):  # watched by their heartbeat
        assert programs_by_name[name].environment == {
            "FLEET_HEARTBEAT": str(tmp_path / "proc" / f"{name}.beat")
        }
        assert f" {name}:" in programs_by_name["hangwatch"].command
    assert "--port 8123" in programs_by_name["web"].command
    assert "--port-base 9100" in programs_by_name["sim"].command
    assert "--port-base 9100" in programs_by_name["links"].command
    assert "-n instructions@%h" in programs_by_name["worker"].command  # supervisord's %% read back as %


def test_the_setup_comes_from_the_environment(tmp_path):
    environ = {"FLEET_PORT": "8400", "FLEET_SIM_PORT_BASE": "9500", "FLEET_VAR_DIR": str(tmp_path)}
    setup = Setup.from_env(environ)
    assert (setup.port, setup.sim_port_base, setup.var_dir, setup.redis_url) == (8400, 9500, tmp_path, None)
    assert setup.env()["REDIS_URL"] == f"unix://{tmp_path / 'redis.sock'}"


def test_the_robots_are_spread_over_as_many_executors_as_asked(tmp_path):
    setup = Setup.from_env({"FLEET_VAR_DIR": str(tmp_path), "FLEET_EXECUTORS": "3"})
    executors = [program for program in programs(setup) if program.name.startswith("executor-")]
    assert [program.name for program in executors] == ["executor-1", "executor-2", "executor-3"]
    assert all(program.command[-2:] == ["manage.py", "executor"] for program in executors)


def test_the_terminal_hears_of_a_death_and_of_giving_up_but_not_of_every_start():
    said = [
        "2026-11-23 23:16:39,933 WARN exited: worker (terminated by SIGKILL; not expected)",
        "2026-11-23 23:16:39,940 INFO spawned: 'worker' with pid 26826",
        "2026-11-23 23:16:43,000 INFO success: worker entered RUNNING state, process has stayed up for > than 3 seconds",
        "2026-11-23 23:17:00,000 INFO gave up: sim entered FATAL state, too many start retries too quickly",
        "2026-11-23 23:15:17,828 CRIT Supervisor is running as root.  Privileges were not dropped",
        "a line that is no log line",
    ]
    assert [supervisor_line(line) for line in said] == [
        "exited: worker (terminated by SIGKILL; not expected)",
        None,
        None,
        "gave up: sim entered FATAL state, too many start retries too quickly",
        None,
        None,
    ]


def test_the_relay_prints_only_new_lines_with_the_name_and_follows_a_rotation(tmp_path):
    layout = Layout(tmp_path)
    layout.log_dir.mkdir()
    layout.log("web").write_text("from an earlier run\n")
    out = io.StringIO()
    relay = LogRelay(layout, ["web", "sim"], out=out)
    with layout.log("web").open("a") as log:
        log.write("listening\nhalf a li")
    relay.flush()
    layout.log("web").rename(layout.log("web").with_suffix(".log.1"))  # supervisord rotates: rename, new file
    layout.log("web").write_text("after the rotation\n")
    with layout.log("web").with_suffix(".log.1").open("a") as old:
        old.write("ne\n")
    relay.flush()
    relay.flush()
    layout.log("sim").write_text("sim started\n")
    relay.flush()
    lines = [line.split(" ", 1)[1] for line in out.getvalue().splitlines()]  # without the time
    assert lines == [
        "web        | listening",
        "web        | half a line",
        "web        | after the rotation",
        "sim        | sim started",
    ]


# ----- production: deploy/ has one unit and one supervisord program per role -----

ROLES = {"web", "executor", "worker", "control", "links", "scheduler", "sim"}
UNITS = {role: f"fleet-{role}.service" for role in ROLES} | {
    "executor": "fleet-executor@.service"
}  # @1, @2...


def _ini(path) -> configparser.ConfigParser:
    parser = configparser.ConfigParser(interpolation=None)
    parser.optionxform = str  # systemd's keys are case-sensitive
    parser.read(path)
    return parser


def test_every_role_has_a_systemd_unit_that_always_restarts_it():
    for role, unit in UNITS.items():
        service = _ini(BASE_DIR / "deploy" / "systemd" / unit)["Service"]
        assert service["Restart"] == "always" and float(service["RestartSec"]) > 0, role
        assert service["ExecStart"].startswith("/opt/fleet/.venv/bin/python "), role
    target = _ini(BASE_DIR / "deploy" / "systemd" / "fleet.target")["Unit"]["Wants"].split()
    wanted = {UNITS[role].replace("@.", "@1.") for role in ROLES - {"sim"}}  # the simulator: on request
    assert set(target) == wanted


def test_the_single_host_supervisord_config_restarts_every_role():
    config = _ini(BASE_DIR / "deploy" / "supervisord.conf")
    programs_by_role = {
        section.split(":")[1]: config[section] for section in config if section.startswith("program:")
    }
    assert set(programs_by_role) == ROLES
    for role, program in programs_by_role.items():
        assert program["autorestart"] == "true" and int(program["startretries"]) >= 100, role
        assert program["stdout_logfile_maxbytes"] == "10MB" and int(program["stdout_logfile_backups"]) > 0, (
            role
        )
    assert config["supervisord"]["logfile_maxbytes"] == "10MB"


def test_the_simulator_takes_more_options_from_the_environment(tmp_path):
    environ = {"FLEET_VAR_DIR": str(tmp_path), "FLEET_SIM_OPTIONS": "--keep-last-command --extra 2"}
    (sim,) = [program for program in programs(Setup.from_env(environ)) if program.name == "sim"]
    assert sim.command[-3:] == ["--keep-last-command", "--extra", "2"]
