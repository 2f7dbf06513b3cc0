"""The layers of docs/ARCHITECTURE.md hold: import-linter's contracts (pyproject.toml) pass on the code, fail on
a wrong-way import, and the plain library imports with Django and Celery unavailable."""

import pkgutil
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

import fleetcore

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = [
    "bench", "fleet", "portal", "experiments", "recordings", "execution", "interpreter", "access", "places",
    "robots", "alerts", "audit", "live", "fleetcore", "simworker",
]  # fmt: skip
LINT_IMPORTS = Path(sys.executable).with_name("lint-imports")


def lint_imports(cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [str(LINT_IMPORTS), "--no-cache"],
        cwd=cwd,
        env={"PYTHONPATH": str(cwd), "PATH": "/usr/bin:/bin"},
        capture_output=True,
        text=True,
        timeout=120,
    )


def test_the_import_contracts_hold():
    result = lint_imports(ROOT)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "0 broken" in result.stdout


@pytest.mark.parametrize(
    ("module", "line", "broken"),
    [
        (
            "robots/wrong_way.py",
            "from execution import dispatch\n",
            "robots is not allowed to import execution",
        ),
        ("fleetcore/wrong_way.py", "import django\n", "The plain library has no Django"),
        (
            "simworker/wrong_way.py",
            "from robots import models\n",
            "The simulator uses the plain library only",
        ),
        ("execution/wrong_way.py", "import bench\n", "execution is not allowed to import bench"),
    ],
)
def test_a_wrong_way_import_breaks_the_contracts(tmp_path, module, line, broken):
    """The same contracts on a copy of the code with one import added the wrong way round."""
    for package in PACKAGES:
        shutil.copytree(
            ROOT / package, tmp_path / package, ignore=shutil.ignore_patterns("__pycache__", "results")
        )
    shutil.copy(ROOT / "pyproject.toml", tmp_path)
    (tmp_path / module).write_text(line)
    result = lint_imports(tmp_path)
    assert result.returncode != 0
    assert broken in result.stdout, result.stdout


def test_the_plain_library_imports_without_django_or_celery():
    """Every fleetcore module, in a Python where importing Django, Celery, Channels or Redis fails."""
    modules = [info.name for info in pkgutil.walk_packages(fleetcore.__path__, "fleetcore.")]
    code = (
        "import sys\n"
        "for name in ('django', 'celery', 'channels', 'redis', 'kombu'):\n"
        "    sys.modules[name] = None  # import name -> ImportError\n"
        f"for name in {modules!r}:\n"
        "    __import__(name)\n"
        "print(len([m for m in sys.modules if m.startswith('fleetcore')]))\n"
    )
    result = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=60, check=False
    )
    assert result.returncode == 0, result.stderr
    assert int(result.stdout) >= len(modules) > 5
