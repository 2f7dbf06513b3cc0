"""The interpreter's grammar for the contract tests (the seed ontology and the paper's fleet, no database)."""

from tests.interpreter.conftest import grammar  # noqa: F401 - the same session fixture
