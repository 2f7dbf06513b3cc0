"""The interpretation's API schema, generated from fleetcore's declarations, never written here a second time.

`Interpretation.wire_form()` gives each key `Interpretation.to_dict` writes, with its type and what it says; the
steps' types are the step contract's wire form, TypedDicts in fleetcore (`fleetcore.steps.StepWire`,
`DestinationWire`, `fleetcore.choice.RobotsWire`). pydantic on Python 3.11 takes only typing_extensions' TypedDict,
so each is rebuilt as one here with the same keys, types, required keys and docstring; tuples become lists and
mappings dicts, as JSON has them. A key added to the dataclass (or to a wire form) is in the schema at once.
"""

import functools
import types
import typing
from collections.abc import Mapping

import typing_extensions
from ninja import Schema
from pydantic import ConfigDict, Field, create_model

from fleetcore.interpretation import Interpretation


def json_type(hint):
    """The type hint as pydantic validates and describes it in JSON (TypedDicts rebuilt, tuples as lists)."""
    if typing.is_typeddict(hint):
        return _typed_dict(hint)
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin is typing.Annotated:  # Annotated[T, "what it says"]: the description
        said = next((meta for meta in hint.__metadata__ if isinstance(meta, str)), None)
        return typing.Annotated[json_type(args[0]), Field(description=said)]
    if origin in (tuple, list):  # tuple[X, ...] or list[X]
        return list[json_type(args[0])]
    if origin in (dict, Mapping):
        return dict[json_type(args[0]), json_type(args[1])]
    if origin in (typing.Union, types.UnionType):
        return typing.Union[tuple(json_type(arg) for arg in args)]  # noqa: UP007 (built from a tuple)
    return hint  # str, float, int, bool, None, a Literal


@functools.cache
def _typed_dict(declared):
    """fleetcore's TypedDict as typing_extensions' (once per class, so the schema names it once). A key the
    declaration does not know is kept, not dropped: the schema says what is sent, never less."""
    required = declared.__required_keys__
    keys = {
        name: (typing_extensions.Required if name in required else typing_extensions.NotRequired)[
            json_type(hint)
        ]
        for name, hint in typing.get_type_hints(declared, include_extras=True).items()
    }
    rebuilt = typing_extensions.TypedDict(declared.__name__, keys)
    rebuilt.__doc__ = declared.__doc__
    rebuilt.__pydantic_config__ = ConfigDict(extra="allow")
    return rebuilt


def schema_of(dataclass) -> type[Schema]:
    """A ninja Schema of the dataclass's wire form: every key required (to_dict writes each), described."""
    keys = {
        name: (json_type(hint), Field(..., description=doc))
        for name, (hint, doc) in dataclass.wire_form().items()
    }
    return create_model(dataclass.__name__, __base__=Schema, __doc__=dataclass.__doc__, **keys)


InterpretationOut = schema_of(Interpretation)
