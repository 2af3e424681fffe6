"""Arrow schemas derived from the record models: the one place a pydantic model becomes
the schema of a Parquet file (as LeRobot derives its features from the dataset's info).

Every Parquet file the project writes is declared by `arrow_schema(<its row model>)`; a
test holds the derived schemas equal to the files written and to the hand-written schemas
they replaced, so the files are byte-identical to before.

Mapping of a field's annotation:
    bool -> bool      int -> int32      float -> float64      str, StrEnum -> string
    `I64` / `F32` (below) -> int64 / float32
    X | None -> X, nullable; every other top-level field is not nullable
    list[X] -> list<X>; fixed size when the list's length is fixed (min_length == max_length)
    tuple[X, X, ...] -> fixed-size list<X> of that length
    dict[str, X] -> map<string, X>
    a nested model -> struct of its fields (nullable, as pyarrow makes struct children)
    Annotated[..., Arrow(t)] -> t as given (e.g. a dict kept as JSON text)
"""

from __future__ import annotations

import types
import typing
from enum import Enum
from typing import Annotated, Any, Union

import annotated_types
import pyarrow as pa
from pydantic import BaseModel
from pydantic.fields import FieldInfo

from pipeline import SCHEMA_VERSION

SCHEMA_METADATA = {"schema_version": str(SCHEMA_VERSION)}


class Arrow:
    """Field metadata: the Arrow type a field is stored as, when the mapping above is not it."""

    def __init__(self, type: pa.DataType):
        self.type = type

    def __repr__(self) -> str:
        return f"Arrow({self.type})"


I64 = Annotated[int, Arrow(pa.int64())]  # seeds: any 64-bit value
F32 = Annotated[float, Arrow(pa.float32())]  # sensor values stored at float32 precision
JSON_TEXT = Arrow(pa.string())  # a dict stored as its JSON text (the row builder dumps it)

_SCALARS = {bool: pa.bool_(), int: pa.int32(), float: pa.float64(), str: pa.string()}


def arrow_schema(model: type[BaseModel], *, metadata: dict[str, str] | None = SCHEMA_METADATA,
                 nullable: bool | None = None) -> pa.Schema:
    """The schema of a table with one row per `model` instance, columns in field order (named
    by their alias, when a field has one).

    `nullable=True` makes every column nullable (a file that was written without a declared
    schema, where pyarrow's inference made them so); None derives it from `X | None`."""
    fields = []
    for name, info in model.model_fields.items():
        try:
            typ, optional = arrow_type(info.annotation, info.metadata)
        except TypeError as e:
            raise TypeError(f"{model.__name__}.{name}: {e}") from None
        column = info.serialization_alias or info.alias or name  # rows are dumped by_alias
        fields.append(pa.field(column, typ, nullable=optional if nullable is None else nullable))
    return pa.schema(fields, metadata=metadata)


def arrow_type(annotation: Any, metadata: list | tuple = ()) -> tuple[pa.DataType, bool]:
    """(the Arrow type of an annotation, whether it admits None)."""
    if typing.get_origin(annotation) is Annotated:
        annotation, *extra = typing.get_args(annotation)
        metadata = [*metadata, *extra]
    optional = False
    if typing.get_origin(annotation) in (Union, types.UnionType):
        args = [a for a in typing.get_args(annotation) if a is not type(None)]
        if len(args) != 1:
            raise TypeError(f"a union other than X | None has no Arrow type: {annotation}")
        optional = len(args) < len(typing.get_args(annotation))
        typ, inner_optional = arrow_type(args[0], metadata)
        return typ, optional or inner_optional
    override = [m for m in metadata if isinstance(m, Arrow)]
    if override:
        return override[-1].type, optional
    origin, args = typing.get_origin(annotation), typing.get_args(annotation)
    if origin is list:
        item, _ = arrow_type(args[0]) if args else (None, False)
        if item is None:
            raise TypeError("a list needs an item type")
        return pa.list_(item, _fixed_length(metadata)), optional
    if origin is tuple:
        if len(args) == 2 and args[1] is Ellipsis:
            return pa.list_(arrow_type(args[0])[0]), optional
        items = {arrow_type(a)[0] for a in args}
        if len(items) != 1:
            raise TypeError(f"a tuple of mixed types has no Arrow type: {annotation}")
        return pa.list_(items.pop(), len(args)), optional
    if origin is dict:
        if not args or args[0] is not str:
            raise TypeError(f"only dict[str, X] maps to an Arrow map: {annotation}")
        return pa.map_(pa.string(), arrow_type(args[1])[0]), optional
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return pa.struct([pa.field(n, arrow_type(f.annotation, f.metadata)[0])
                          for n, f in annotation.model_fields.items()]), optional
    if isinstance(annotation, type) and issubclass(annotation, Enum):
        if not issubclass(annotation, str):
            raise TypeError(f"only string enums map to Arrow strings: {annotation}")
        return pa.string(), optional
    if annotation in _SCALARS:
        return _SCALARS[annotation], optional
    raise TypeError(f"no Arrow type for {annotation!r}")


def _fixed_length(metadata) -> int:
    """The fixed length of a list (pydantic's min_length == max_length), else -1 (variable)."""
    lo = hi = None
    for m in metadata:
        if isinstance(m, FieldInfo):  # Annotated[list[X], Field(min_length=.., max_length=..)]
            n = _fixed_length(m.metadata)
            lo = hi = n if n >= 0 else None
        elif isinstance(m, annotated_types.Len):
            lo, hi = m.min_length, m.max_length
        elif isinstance(m, annotated_types.MinLen):
            lo = m.min_length
        elif isinstance(m, annotated_types.MaxLen):
            hi = m.max_length
    return lo if lo is not None and lo == hi else -1
