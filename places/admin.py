from django.contrib import admin

from places.models import Location, Map


class LocationInline(admin.TabularInline):
    model = Location
    extra = 0


@admin.register(Map)
class MapAdmin(admin.ModelAdmin):
    list_display = ("name", "width", "height", "resolution", "source")
    exclude = ("data",)
    inlines = [LocationInline]


@admin.register(Location)
class LocationAdmin(admin.ModelAdmin):
    list_display = ("name", "map", "x", "y", "yaw", "kind")
    list_filter = ("map", "kind")
    search_fields = ("name",)
