from django.apps import AppConfig


class SimworkerConfig(AppConfig):
    name = "simworker"
