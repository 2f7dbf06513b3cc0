"""A bad setting stops start-up with one line naming the variable."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

BASE_DIR = Path(__file__).resolve().parents[2]

BAD_VALUES = [
    ("DATABASE_URL", "mysql://nope/x"),
    ("DATABASE_URL", "postgres://"),
    ("REDIS_URL", "http://127.0.0.1:6379"),
    ("REDIS_URL", "redis://127.0.0.1:notaport/0"),
    ("FLEET_DEBUG", "maybe"),
    ("ALLOWED_HOSTS", "a,,b"),
    ("SECRET_KEY", "short"),
    ("FLEET_ADMIN_PASSWORD", "123"),
]


@pytest.mark.parametrize(("name", "value"), BAD_VALUES)
def test_bad_setting_names_the_variable(name, value, tmp_path):
    env = {**os.environ, name: value, "FLEET_VAR_DIR": str(tmp_path)}
    result = subprocess.run(
        [sys.executable, "manage.py", "check"],
        cwd=BASE_DIR,
        env=env,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert result.returncode != 0
    last_line = result.stderr.strip().splitlines()[-1]
    assert "ImproperlyConfigured" in last_line
    assert name in last_line


def test_secret_key_is_generated_once_into_var(tmp_path):
    env = {k: v for k, v in os.environ.items() if k != "SECRET_KEY"} | {"FLEET_VAR_DIR": str(tmp_path)}
    code = "from django.conf import settings; print(settings.SECRET_KEY)"
    run = lambda: subprocess.run(  # noqa: E731
        [
            sys.executable,
            "-c",
            f"import django, os; os.environ.setdefault('DJANGO_SETTINGS_MODULE', 'fleet.settings'); django.setup(); {code}",
        ],
        cwd=BASE_DIR,
        env=env,
        capture_output=True,
        text=True,
        timeout=60,
        check=True,
    ).stdout.strip()
    first, second = run(), run()
    assert first == second == (tmp_path / "secret_key").read_text()
    assert len(first) >= 50
