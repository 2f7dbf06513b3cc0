from django.apps import AppConfig


class AccessConfig(AppConfig):
    name = "access"
    verbose_name = "Access"

    def ready(self):
        from django.db.models.signals import post_migrate

        post_migrate.connect(_sync_roles, dispatch_uid="access.sync_roles")


def _sync_roles(sender, app_config=None, **kwargs):
    """After the last app migrates, create the role groups with every permission in place."""
    from django.apps import apps
    from django.contrib.auth.management import create_permissions

    if sender.name != "simworker":  # the last of our apps in INSTALLED_APPS
        return
    for config in apps.get_app_configs():
        create_permissions(config, verbosity=0)
    from access.roles import sync_groups

    sync_groups()
