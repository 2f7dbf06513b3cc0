"""The ontology's topic keywords and action synonyms, given to robot registration (a vocabulary source)."""

from django.db import DatabaseError

from interpreter.models import Synonym, TopicKeyword
from robots import identify


def add_ontology_vocabulary(vocab: identify.Vocabulary) -> None:
    """Replace a role's keywords by its TopicKeyword rows, where it has any; add the ontology's synonyms."""
    try:
        rows = list(TopicKeyword.objects.values_list("action", "keyword", "weight"))
        synonyms = list(
            Synonym.objects.filter(action__name__in=identify.ACTIONS).values_list("action__name", "word")
        )
    except DatabaseError:  # no ontology tables yet (a fresh database): the roles' own keywords serve
        return
    from_db: dict[str, dict[str, float]] = {}
    for action, keyword, weight in rows:
        from_db.setdefault(action, {})[keyword] = weight
    vocab.keywords.update(from_db)
    for action, word in synonyms:
        vocab.synonyms.setdefault(action, set()).add(word.replace(" ", "_"))
