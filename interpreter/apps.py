from django.apps import AppConfig


class InterpreterConfig(AppConfig):
    name = "interpreter"

    def ready(self):
        from interpreter import signals  # noqa: F401 - connects the ontology and fleet version bumps

        # Deferred: apps.py is imported before the app registry is ready, and both modules import models.
        from interpreter.vocabulary import add_ontology_vocabulary
        from robots import registration

        if add_ontology_vocabulary not in registration.vocabulary_sources:
            registration.vocabulary_sources.append(add_ontology_vocabulary)
