"""The layers of docs/ARCHITECTURE.md hold: import-linter's contracts (pyproject.toml) pass on the code, fail on
a wrong-way import, and the plain library imports with Django and Celery unavailable; no module is in an import
cycle, inside a package or across packages, with the imports deferred into functions counted."""

import ast
import pkgutil
import shutil
import subprocess
import sys
from pathlib import Path

import grimp
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


def module_cycles(*packages: str) -> list[list[str]]:
    """The import cycles between the modules of these packages, each as its modules (a strongly connected
    component of the import graph, Tarjan's). grimp reads every import statement: at the top, deferred into a
    function, under TYPE_CHECKING; an import by dotted path (import_string) is no statement and none is used."""
    graph = grimp.build_graph(*packages, cache_dir=None)
    edges = {module: graph.find_modules_directly_imported_by(module) for module in graph.modules}
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    cycles = []

    def visit(module: str) -> None:  # (recursive: the graph is some hundreds of modules deep at most)
        index[module] = low[module] = len(index)
        stack.append(module)
        for imported in edges[module]:
            if imported not in index:
                visit(imported)
                low[module] = min(low[module], low[imported])
            elif imported in stack:
                low[module] = min(low[module], index[imported])
        if low[module] == index[module]:
            component = [stack.pop()]
            while component[-1] != module:
                component.append(stack.pop())
            if len(component) > 1 or module in edges[module]:
                cycles.append(sorted(component))

    for module in sorted(edges):
        if module not in index:
            visit(module)
    return cycles


def test_no_module_is_in_an_import_cycle():
    assert module_cycles(*PACKAGES) == []


def test_a_cycle_through_an_import_deferred_into_a_function_is_found(tmp_path, monkeypatch):
    """The checker on a tiny package: a imports b at the top, b imports a inside a function; c stands apart."""
    package = tmp_path / "planted"
    package.mkdir()
    (package / "__init__.py").write_text("")
    (package / "a.py").write_text("from planted import b\n")
    (package / "b.py").write_text("def later():\n    from planted import a\n\n    return a\n")
    (package / "c.py").write_text("from planted import a\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    assert module_cycles("planted") == [["planted.a", "planted.b"]]
    (package / "b.py").write_text("def later():\n    return 1\n")
    assert module_cycles("planted") == []


INTERPRETATION_KEYS = {"type", "valid", "needs_user", "question"}  # what only an interpretation's dict has


def hand_built_interpretations(root: Path, packages: list[str]) -> list[str]:
    """Where product code writes an interpretation as a dict literal ({"type": ..., "steps": [...]}) instead of
    `fleetcore.interpretation.Interpretation` (its own `to_dict` excepted): "path:line" each."""
    found = []
    for package in packages:
        for path in sorted((root / package).rglob("*.py")):
            if "migrations" in path.parts or path.name == "interpretation.py":
                continue
            for node in ast.walk(ast.parse(path.read_text(), str(path))):
                keys = {k.value for k in getattr(node, "keys", ()) if isinstance(k, ast.Constant)}
                if isinstance(node, ast.Dict) and "steps" in keys and keys & INTERPRETATION_KEYS:
                    found.append(f"{path.relative_to(root)}:{node.lineno}")
    return found


def test_no_interpretation_is_built_by_hand(tmp_path):
    assert hand_built_interpretations(ROOT, PACKAGES) == []
    (tmp_path / "planted").mkdir()
    (tmp_path / "planted" / "make_way.py").write_text(
        'parse = {"type": "I", "steps": [{"action": "stop"}]}\n'
    )
    assert hand_built_interpretations(tmp_path, ["planted"]) == ["planted/make_way.py:1"]
