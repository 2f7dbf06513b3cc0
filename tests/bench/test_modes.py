"""`make bench` passes its mode to every component bench: each must take both flags (full once failed here)."""

import subprocess
import sys

import pytest

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
