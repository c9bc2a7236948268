"""CiA 402 in one home: services/control names the CiA 402 objects by the names ``device/drive/cia402.py`` gives
them, never by a ref literal of its own ("0x6060"); its texts and docstrings may still cite the objects."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

from drivebench.device.drive import cia402
from drivebench.device.profiles.addressing import IndexRef, parse_ref

CONTROL = Path(__file__).resolve().parents[2] / "backend" / "drivebench" / "services" / "control"
REF = re.compile(r"0x6[0-9a-f]{3}(?:\.\d*)?", re.IGNORECASE)
"""An object ref as code writes it (``0x6060``, ``0x607D.1``, the ``0x60E3.`` of an f-string), not a text citing
one (``... max profile velocity 0x607F = {top}``)."""


def ref_literals(source: str) -> list[str]:
    """The CiA 402 object refs written as literals in the code (texts that only cite an object do not count)."""
    return [node.value for node in ast.walk(ast.parse(source))
            if isinstance(node, ast.Constant) and isinstance(node.value, str) and REF.fullmatch(node.value)]


def test_services_control_writes_no_cia402_ref_of_its_own() -> None:
    found = {path.name: names for path in sorted(CONTROL.glob("*.py"))
             if (names := ref_literals(path.read_text(encoding="utf-8")))}
    assert not found, f"CiA 402 objects named by literal instead of device/drive/cia402.py's names: {found}"


@pytest.mark.parametrize(("code", "refs"), [
    ('await read(session, 1, "0x6061")\n', ["0x6061"]),
    ('refs = [f"0x60E3.{sub}" for sub in subs]\n', ["0x60E3."]),
    ('LIMITS = ("0x607D.1", "0x607D.2")\n', ["0x607D.1", "0x607D.2"]),
    ('text = _("Jog speed {speed} is above 0x607F = {top}.")\nx = f"{MODES_OF_OPERATION}.1"\n', []),
])
def test_the_check_finds_ref_literals_not_cited_objects(code: str, refs: list[str]) -> None:
    assert ref_literals(code) == refs


def test_the_named_objects_are_cia402_refs() -> None:
    named = {name: value for name, value in vars(cia402).items()
             if name.isupper() and isinstance(value, str) and REF.fullmatch(value)}
    assert len(named) >= 30
    for name, value in named.items():
        ref = parse_ref(value)
        assert isinstance(ref, IndexRef) and 0x6000 <= ref.index <= 0x67FF, name
    assert (cia402.CONTROL_WORD, cia402.STATUS_WORD, cia402.MODES_OF_OPERATION) == ("0x6040", "0x6041", "0x6060")
    assert (cia402.MIN_POSITION_LIMIT, cia402.MAX_POSITION_LIMIT) == ("0x607D.1", "0x607D.2")
