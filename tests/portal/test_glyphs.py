"""Every symbol the pages show has a font on a plain Debian machine (no emoji font): none renders as a box."""

import shutil
import subprocess
from pathlib import Path

import pytest

BASE_DIR = Path(__file__).resolve().parents[2]
SOURCES = [
    *BASE_DIR.glob("templates/**/*.html"),
    *BASE_DIR.glob("static/fleet/*.js"),
    *BASE_DIR.glob("static/fleet/*.css"),
]


@pytest.mark.skipif(shutil.which("fc-list") is None, reason="fontconfig's fc-list is not installed")
def test_every_symbol_on_the_pages_has_an_installed_font():
    symbols = {char for path in SOURCES for char in path.read_text() if ord(char) >= 0x2000}
    assert "‖" in symbols  # the stop-hold mark, which was ⏸ (no font covers it without an emoji font)
    missing = [
        f"{char} U+{ord(char):04X}"
        for char in sorted(symbols)
        if not subprocess.run(
            ["fc-list", f":charset={ord(char):x}", "family"], capture_output=True, text=True, timeout=30
        ).stdout.strip()
    ]
    assert not missing, missing
