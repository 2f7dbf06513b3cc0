from django.apps import AppConfig


class InterpreterConfig(AppConfig):
    name = "interpreter"

    def ready(self):
        from interpreter import signals  # noqa: F401 - connects the ontology and fleet version bumps
