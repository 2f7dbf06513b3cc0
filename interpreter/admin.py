"""The ontology's terms in the Django admin; every save bumps the ontology version (see signals)."""

from django.contrib import admin

from interpreter.models import (
    ActionConcept,
    DestinationClass,
    DestinationConcept,
    Lesson,
    OntologyVersion,
    Synonym,
    TopicKeyword,
)


class SynonymInline(admin.TabularInline):
    model = Synonym
    extra = 1
    fields = ["word"]


@admin.register(ActionConcept)
class ActionConceptAdmin(admin.ModelAdmin):
    list_display = ["name", "category", "takes_destination", "requires_destination", "countable"]
    list_filter = ["category"]
    filter_horizontal = ["accepts"]
    inlines = [SynonymInline]
    search_fields = ["name", "synonyms__word"]


@admin.register(DestinationClass)
class DestinationClassAdmin(admin.ModelAdmin):
    list_display = ["name", "parent", "on_map", "description"]
    list_filter = ["on_map"]


@admin.register(DestinationConcept)
class DestinationConceptAdmin(admin.ModelAdmin):
    list_display = ["name", "destination_class", "description"]
    list_filter = ["destination_class"]
    inlines = [SynonymInline]
    search_fields = ["name"]


@admin.register(Synonym)
class SynonymAdmin(admin.ModelAdmin):
    list_display = ["word", "action", "concept"]
    list_filter = ["action"]
    search_fields = ["word"]


@admin.register(TopicKeyword)
class TopicKeywordAdmin(admin.ModelAdmin):
    list_display = ["action", "keyword", "weight"]
    list_filter = ["action"]
    list_editable = ["weight"]


@admin.register(Lesson)
class LessonAdmin(admin.ModelAdmin):
    list_display = ["taught_at", "taught_by", "kind", "word", "meaning", "text"]
    list_filter = ["kind"]
    readonly_fields = ["taught_at", "taught_by", "instruction"]
    search_fields = ["word", "text"]


@admin.register(OntologyVersion)
class OntologyVersionAdmin(admin.ModelAdmin):
    list_display = ["number", "changed_at", "token"]
    readonly_fields = ["number", "changed_at", "token"]
