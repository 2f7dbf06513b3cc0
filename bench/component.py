"""What the component benches share: their command line and where their JSON goes.

    python -m bench.<name> [--quick | --full] [--out DIR]

`bench.run` runs each with the run's mode and its --out, so a run written elsewhere leaves bench/results alone.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "results"


def parser(description: str) -> argparse.ArgumentParser:
    """--quick / --full (the default) as args.mode, and --out (bench/results by default)."""
    parser = argparse.ArgumentParser(description=description)
    modes = parser.add_mutually_exclusive_group()
    modes.add_argument("--quick", action="store_const", const="quick", dest="mode", help="a short version")
    modes.add_argument("--full", action="store_const", const="full", dest="mode", help="the default")
    parser.set_defaults(mode="full")
    parser.add_argument("--out", type=Path, default=RESULTS, help="the directory to write the JSON into")
    return parser


def write(out: Path, filename: str, data: dict) -> Path:
    """Write data as out/filename (indented JSON) and return the path."""
    out.mkdir(parents=True, exist_ok=True)
    path = out / filename
    path.write_text(json.dumps(data, indent=2) + "\n")
    return path
