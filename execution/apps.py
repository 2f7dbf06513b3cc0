from django.apps import AppConfig


class ExecutionConfig(AppConfig):
    name = "execution"
    verbose_name = "Execution"

    def ready(self):
        # here, not at the top: these modules import models, which the app registry has loaded only now
        from execution import instructions, schedules, signals
        from places.signals import world_loaded
        from robots.signals import robots_registered

        world_loaded.connect(schedules.on_world_loaded, dispatch_uid="execution.world_schedules")
        robots_registered.connect(schedules.on_robots_registered, dispatch_uid="execution.robot_schedules")
        # traffic asks for make_way instructions through a signal: it never imports the instruction layer above it
        signals.make_way_asked.connect(instructions.on_make_way_asked, dispatch_uid="execution.make_way")
