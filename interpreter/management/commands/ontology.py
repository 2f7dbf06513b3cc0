"""Export the ontology as OWL RDF/XML, or import terms from it: `ontology export PATH|-`, `ontology import PATH`."""

import sys
from pathlib import Path

from django.core.management.base import BaseCommand, CommandError

from interpreter.service import export_ontology, import_ontology


class Command(BaseCommand):
    help = "Export the robot ontology as OWL (RDF/XML) or import its terms from such a file."

    def add_arguments(self, parser):
        sub = parser.add_subparsers(dest="verb", required=True)
        export = sub.add_parser("export", help="write OWL RDF/XML to PATH, or - for stdout")
        export.add_argument("path")
        imp = sub.add_parser("import", help="replace the editable terms with those of an OWL RDF/XML file")
        imp.add_argument("path")

    def handle(self, *args, verb, path, **options):
        if verb == "export":
            self._export(path)
        else:
            self._import(path)

    def _export(self, path: str) -> None:
        data = export_ontology()
        if path == "-":
            sys.stdout.buffer.write(data)
            sys.stdout.flush()
            return
        try:
            Path(path).write_bytes(data)
        except OSError as exc:
            raise CommandError(f"cannot write {path}: {exc.strerror}") from exc
        self.stderr.write(f"wrote {len(data)} bytes to {path}")

    def _import(self, path: str) -> None:
        try:
            data = sys.stdin.buffer.read() if path == "-" else Path(path).read_bytes()
        except OSError as exc:
            raise CommandError(f"cannot read {path}: {exc.strerror}") from exc
        try:
            terms = import_ontology(data)
        except ValueError as exc:
            raise CommandError(str(exc)) from exc
        self.stdout.write(
            f"imported {len(terms.actions)} actions, {len(terms.synonyms)} synonyms, "
            f"{len(terms.concepts)} concepts, {len(terms.classes)} classes, {len(terms.keywords)} keywords"
        )
