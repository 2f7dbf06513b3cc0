from django.contrib import admin

from robots.models import Binding, Node, Param, RegistrationRecord, Robot, Service, StateTransition, Topic


class BindingInline(admin.TabularInline):
    model = Binding
    extra = 0
    fields = ("action", "target", "kind", "message_type", "how", "confidence", "needs_user")


@admin.register(Robot)
class RobotAdmin(admin.ModelAdmin):
    list_display = (
        "name",
        "model",
        "drive",
        "wheel_count",
        "endpoint",
        "namespace",
        "ros_version",
        "link_status",
        "state",
    )
    list_filter = ("drive", "link_status", "state", "ros_version")
    search_fields = ("name", "model", "endpoint")
    inlines = [BindingInline]


@admin.register(Topic)
class TopicAdmin(admin.ModelAdmin):
    list_display = ("name", "type", "robot")
    list_filter = ("robot",)
    search_fields = ("name", "type")


@admin.register(Node)
class NodeAdmin(admin.ModelAdmin):
    list_display = ("name", "robot")
    list_filter = ("robot",)
    search_fields = ("name",)


@admin.register(Service)
class ServiceAdmin(admin.ModelAdmin):
    list_display = ("name", "type", "robot")
    list_filter = ("robot",)
    search_fields = ("name", "type")


@admin.register(Param)
class ParamAdmin(admin.ModelAdmin):
    list_display = ("name", "robot")
    list_filter = ("robot",)
    search_fields = ("name",)


@admin.register(Binding)
class BindingAdmin(admin.ModelAdmin):
    list_display = ("robot", "action", "target", "how", "confidence", "needs_user")
    list_filter = ("action", "how", "needs_user")


@admin.register(RegistrationRecord)
class RegistrationRecordAdmin(admin.ModelAdmin):
    list_display = ("endpoint", "started_at", "finished_at", "ok", "user")
    list_filter = ("ok",)


@admin.register(StateTransition)
class StateTransitionAdmin(admin.ModelAdmin):
    list_display = ("robot", "from_state", "to_state", "at", "instruction", "reason")
    list_filter = ("robot", "to_state")
