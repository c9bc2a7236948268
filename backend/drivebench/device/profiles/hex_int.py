"""Integers the profile files write as ``"0x5FA7"`` (or a plain number): ``HexInt``."""

from __future__ import annotations

from typing import Annotated, Any

from pydantic import BeforeValidator, PlainSerializer, WithJsonSchema


def _parse_int(value: Any) -> Any:
    """Accept ints and strings like ``"0x5FA7"``, ``"24487"``, ``"0o17"`` in profile files."""
    if isinstance(value, str):
        return int(value.strip(), 0)
    return value


# The published schema accepts what the files hold: an integer or a string like "0x5FA7".
HEX_INT_PATTERN = r"^\s*[-+]?(0[xX][0-9a-fA-F_]+|0[oO][0-7_]+|[0-9_]+)\s*$"
HEX_INT_SCHEMA: dict[str, Any] = {"anyOf": [{"type": "integer"}, {"type": "string", "pattern": HEX_INT_PATTERN}]}
HexInt = Annotated[int, BeforeValidator(_parse_int), PlainSerializer(lambda v: f"0x{v:04X}", return_type=str),
                   WithJsonSchema(HEX_INT_SCHEMA)]
