from django.apps import AppConfig
from django.conf import settings
from django.core.signals import setting_changed

from robots import limits
from robots.rosbridge import inflow


class RobotsConfig(AppConfig):
    name = "robots"

    def ready(self):
        """Put the caps on what robots may send (robots.limits) in force, and again when a test changes one;
        listen for endpoints that flood their links."""
        configure_limits()
        setting_changed.connect(_on_setting_changed, dispatch_uid="robots.limits")
        # Deferred: apps.py is imported before the app registry is ready, and flooding imports the models.
        from robots import flooding

        if flooding.flooded not in inflow.LISTENERS:  # a flooding endpoint flags its robots, raises an alert
            inflow.LISTENERS.append(flooding.flooded)


def configure_limits() -> None:
    limits.configure(
        limits.Limits(
            frame_bytes=settings.FLEET_ROBOT_MAX_FRAME_MB * limits.MB,
            topics=settings.FLEET_ROBOT_MAX_TOPICS,
            urdf_bytes=settings.FLEET_ROBOT_MAX_URDF_MB * limits.MB,
            frames_per_s=settings.FLEET_ROBOT_MAX_FRAMES_PER_S,
        )
    )


def _on_setting_changed(setting, **kwargs) -> None:
    if setting.startswith("FLEET_ROBOT_MAX_"):
        configure_limits()
