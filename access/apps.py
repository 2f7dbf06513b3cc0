from django.apps import AppConfig, apps
from django.contrib.auth.management import create_permissions
from django.db.models.signals import post_migrate


class AccessConfig(AppConfig):
    name = "access"
    verbose_name = "Access"

    def ready(self):
        post_migrate.connect(_sync_roles, dispatch_uid="access.sync_roles")


def _sync_roles(sender, app_config=None, **kwargs):
    """After the last app migrates, create the role groups with every permission in place."""
    if sender.name != "simworker":  # the last of our apps in INSTALLED_APPS
        return
    for config in apps.get_app_configs():
        create_permissions(config, verbosity=0)
    # Deferred: apps.py is imported before the app registry is ready, and roles imports the auth models.
    from access.roles import sync_groups

    sync_groups()
