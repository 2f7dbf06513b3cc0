"""`make bench` passes its mode to every component bench: each must take both flags (full once failed here)."""

import json
import subprocess
import sys

import pytest

from bench.component import RESULTS as COMPONENT_RESULTS
from bench.run import COMPONENTS, MODES


@pytest.mark.parametrize("mode", sorted(MODES))
@pytest.mark.parametrize("name", sorted(COMPONENTS))
def test_each_component_bench_takes_the_mode_flag(name, mode):
    proc = subprocess.run(
        [sys.executable, "-m", f"bench.{name}", f"--{mode}", "--help"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 0, proc.stderr
    assert f"--{mode}" in proc.stdout


def test_a_component_bench_writes_where_it_is_told(tmp_path):
    """`bench.run --out DIR` hands DIR down: the committed results under bench/results stay as they are."""
    committed = COMPONENT_RESULTS / "interpreter.json"
    before = committed.read_bytes() if committed.exists() else None
    proc = subprocess.run(
        [sys.executable, "-m", "bench.interpreter_throughput", "--quick", "--out", str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 0, proc.stderr
    written = json.loads((tmp_path / "interpreter.json").read_text())
    assert written["interpreter_per_s"] > 0 and written["seconds"] == 1.0
    assert (committed.read_bytes() if committed.exists() else None) == before
