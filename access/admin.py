from django.contrib import admin

from access.models import ControlLease


@admin.register(ControlLease)
class ControlLeaseAdmin(admin.ModelAdmin):
    list_display = ("robot", "user", "taken_at", "expires_at")
