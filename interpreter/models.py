"""The ontology's editable terms (edited in the admin) and the lessons people taught."""

from django.conf import settings
from django.core.validators import RegexValidator
from django.db import models
from django.db.models import Q
from django.utils import timezone

from interpreter.terms import ActionTerm, ClassTerm, ConceptTerm, KeywordTerm, SynonymTerm, Terms
from robots.models import Robot

identifier = RegexValidator(
    r"^[A-Za-z][A-Za-z0-9_]*$", "Use letters, digits and underscores, starting with a letter."
)


class DestinationClass(models.Model):
    """A class of destinations (Location, Room, ... or NotAPlace); on_map classes are places robots go to."""

    name = models.CharField(max_length=60, unique=True, validators=[identifier])
    parent = models.ForeignKey(
        "self", null=True, blank=True, on_delete=models.PROTECT, related_name="children"
    )
    on_map = models.BooleanField(default=False, help_text="a place on the map robots can go to")
    description = models.CharField(
        max_length=200, blank=True, help_text="in words, e.g. 'a part of a building'"
    )

    class Meta:
        ordering = ["name"]
        verbose_name_plural = "destination classes"

    def __str__(self):
        return self.name


class ActionConcept(models.Model):
    """An action robots can be told to do, with the destination classes it accepts (owl:allValuesFrom)."""

    class Category(models.TextChoices):
        MOTION = "motion"
        TASK = "task"
        CONTROL = "control"
        QUERY = "query"

    name = models.CharField(max_length=60, unique=True, validators=[identifier])
    category = models.CharField(max_length=10, choices=Category.choices, default=Category.MOTION)
    takes_destination = models.BooleanField(default=False)
    requires_destination = models.BooleanField(default=False)
    countable = models.BooleanField(default=False, help_text="takes a count, e.g. rotate(5)")
    accepts = models.ManyToManyField(
        DestinationClass, blank=True, related_name="actions", help_text="destination classes allowed"
    )
    description = models.CharField(max_length=200, blank=True)

    class Meta:
        ordering = ["name"]

    def __str__(self):
        return self.name


class DestinationConcept(models.Model):
    """A thing people may name as a destination; roof is known but not a valid destination."""

    name = models.CharField(max_length=60, unique=True)
    destination_class = models.ForeignKey(DestinationClass, on_delete=models.PROTECT, related_name="concepts")
    description = models.CharField(max_length=200, blank=True)

    class Meta:
        ordering = ["name"]

    def __str__(self):
        return self.name

    def save(self, *args, **kwargs):
        self.name = self.name.strip().casefold()
        super().save(*args, **kwargs)


class Synonym(models.Model):
    """A word that is owl:sameAs an action concept or a destination concept."""

    word = models.CharField(max_length=60, unique=True)
    action = models.ForeignKey(
        ActionConcept, null=True, blank=True, on_delete=models.CASCADE, related_name="synonyms"
    )
    concept = models.ForeignKey(
        DestinationConcept, null=True, blank=True, on_delete=models.CASCADE, related_name="synonyms"
    )

    class Meta:
        ordering = ["word"]
        constraints = [
            models.CheckConstraint(
                condition=Q(action__isnull=False, concept__isnull=True)
                | Q(action__isnull=True, concept__isnull=False),
                name="synonym_of_exactly_one_concept",
            )
        ]

    def __str__(self):
        return f"{self.word} = {self.action or self.concept}"

    def save(self, *args, **kwargs):
        self.word = " ".join(self.word.casefold().split())
        super().save(*args, **kwargs)


class TopicKeyword(models.Model):
    """A topic-name keyword for an action of the registration engine (the paper's lists)."""

    action = models.CharField(max_length=40, help_text="move, navigate, odometry, scan, map, pose, ...")
    keyword = models.CharField(max_length=60)
    weight = models.FloatField(default=1.0)

    class Meta:
        ordering = ["action", "keyword"]
        constraints = [models.UniqueConstraint(fields=["action", "keyword"], name="topic_keyword_unique")]

    def __str__(self):
        return f"{self.action}: {self.keyword}"


class Lesson(models.Model):
    """Something a person taught the ontology, with who and when."""

    class Kind(models.TextChoices):
        SYNONYM = "synonym"
        NOT_A_PLACE = "not_a_place"
        LOCATION = "location"
        FORGET = "forget"

    taught_by = models.ForeignKey(settings.AUTH_USER_MODEL, null=True, blank=True, on_delete=models.SET_NULL)
    taught_at = models.DateTimeField(default=timezone.now)
    text = models.TextField(help_text="the answer as the person typed it")
    kind = models.CharField(max_length=12, choices=Kind.choices)
    word = models.CharField(max_length=60)
    meaning = models.CharField(max_length=100, blank=True)
    instruction = models.ForeignKey(
        "execution.Instruction", null=True, blank=True, on_delete=models.SET_NULL, related_name="lessons"
    )

    class Meta:
        ordering = ["-taught_at"]

    def __str__(self):
        return self.text


class OntologyVersion(models.Model):
    """One row: bumped on every edit of a term, so every process rebuilds on its next instruction."""

    number = models.PositiveBigIntegerField(default=0)
    token = models.CharField(max_length=40, blank=True)
    changed_at = models.DateTimeField(default=timezone.now)

    def __str__(self):
        return f"ontology v{self.number}"


def load_terms() -> Terms:
    """Read every editable term from the database."""
    actions = [
        ActionTerm(
            a.name, a.category, a.takes_destination, a.requires_destination, a.countable,
            tuple(sorted(c.name for c in a.accepts.all())), a.description,
        )
        for a in ActionConcept.objects.prefetch_related("accepts")
    ]  # fmt: skip
    classes = [
        ClassTerm(c.name, c.parent.name if c.parent else None, c.on_map, c.description)
        for c in DestinationClass.objects.select_related("parent")
    ]
    concepts = [
        ConceptTerm(c.name, c.destination_class.name, c.description)
        for c in DestinationConcept.objects.select_related("destination_class")
    ]
    synonyms = [
        SynonymTerm(s.word, s.action.name if s.action else None, s.concept.name if s.concept else None)
        for s in Synonym.objects.select_related("action", "concept")
    ]
    keywords = [KeywordTerm(k.action, k.keyword, k.weight) for k in TopicKeyword.objects.all()]
    models_ = sorted(set(Robot.objects.exclude(model="").values_list("model", "drive")))
    return Terms(actions, classes, concepts, synonyms, keywords, models_)
