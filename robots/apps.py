from django.apps import AppConfig
from django.core.signals import setting_changed


class RobotsConfig(AppConfig):
    name = "robots"

    def ready(self):
        """Put the caps on what robots may send (robots.limits) in force, and again when a test changes one."""
        configure_limits()
        setting_changed.connect(_on_setting_changed, dispatch_uid="robots.limits")


def configure_limits() -> None:
    from django.conf import settings

    from robots import limits

    limits.configure(
        limits.Limits(
            frame_bytes=settings.FLEET_ROBOT_MAX_FRAME_MB * limits.MB,
            topics=settings.FLEET_ROBOT_MAX_TOPICS,
            urdf_bytes=settings.FLEET_ROBOT_MAX_URDF_MB * limits.MB,
        )
    )


def _on_setting_changed(setting, **kwargs) -> None:
    if setting.startswith("FLEET_ROBOT_MAX_"):
        configure_limits()
