"""Interpret instructions: `interpret --json "TEXT"` or `interpret --file PATH|-` (one JSON per line)."""

import json
import sys

from django.core.management.base import BaseCommand, CommandError

from interpreter.service import interpret


class Command(BaseCommand):
    help = "Interpret an instruction (or one per line of a file) and print the result as JSON."

    def add_arguments(self, parser):
        parser.add_argument("text", nargs="?", help="the instruction")
        parser.add_argument("--json", action="store_true", help="print JSON (the default output)")
        parser.add_argument("--file", help="read one instruction per line from PATH, or - for stdin")

    def handle(self, *args, text=None, file=None, **options):
        if (text is None) == (file is None):
            raise CommandError('give either an instruction ("TEXT") or --file PATH|-')
        if text is not None:
            self._print(interpret(text).to_dict())
            return
        for line in self._lines(file):
            if line.strip():
                self._print(interpret(line.rstrip("\r\n")).to_dict())

    def _lines(self, file):
        if file == "-":
            yield from sys.stdin
            return
        try:
            with open(file, encoding="utf-8", errors="replace") as handle:
                yield from handle
        except OSError as exc:
            raise CommandError(f"cannot read {file}: {exc.strerror}") from exc

    def _print(self, result: dict) -> None:
        self.stdout.write(json.dumps(result, ensure_ascii=False))
