from django.apps import AppConfig


class ExecutionConfig(AppConfig):
    name = "execution"
    verbose_name = "Execution"

    def ready(self):
        from execution import schedules
        from places.signals import world_loaded
        from robots.signals import robots_registered

        world_loaded.connect(schedules.on_world_loaded, dispatch_uid="execution.world_schedules")
        robots_registered.connect(schedules.on_robots_registered, dispatch_uid="execution.robot_schedules")
