"""Device behaviour lives in profiles: the code of services/, web/, protocol/, simulator/ and device/ names no vendor
or drive family.

A grep over the code, not the prose: names (functions, classes, variables, attributes, arguments, imports) and
string literals are checked; comments and docstrings may cite the manuals ("8400 motec manual ch. 9.1"). A device
family's behaviour goes into its profile's sections (``device/*.py`` models, ``device_profiles/*.json``); what
cannot be data is a named behaviour a profile selects by name, and only ``NAMED_BEHAVIOURS`` modules may name one.
"""

from __future__ import annotations

import ast
import re
from collections import Counter
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "backend" / "drivebench"
SCOPES = ("services", "web", "protocol", "simulator", "device")
VENDOR = re.compile(r"lenze|siemens|micromaster|motec|baseline[ _-]?c\b|emf2178|(?<![a-z])emf(?:_|\b)|(?<![a-z])mm4"
                    r"|93xx|(?<![a-z\d.])8[24]00(?!\d)", re.IGNORECASE)
"""A family name also inside a longer name (``is_8400``, ``WORDS_EMF``), not inside a number or ``ETG.8200``."""

NAMED_BEHAVIOURS: set[str] = {
    "services/control/drive_words.py",  # the state-machine kinds a control section selects: cia402 / lenze / none
}
"""Modules that hold the table of named behaviours a profile selects by name (they may name a family)."""

KNOWN_EXCEPTIONS: dict[str, int] = {
    "simulator/lenze_control.py": 44,
    "simulator/node.py": 7,
    "simulator/pdo.py": 4,
    "device/calculators/cable.py": 1,
    "device/drive/control.py": 1,
    "device/formats/eds_export.py": 2,
    "device/profiles/addressing.py": 14,
    "device/profiles/catalog.py": 9,
    "device/profiles/profile.py": 10,
}
"""Modules that still name a vendor, with how many names each may hold: the numbers only go down."""


def _docstrings(tree: ast.AST) -> set[int]:
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef):
            body = node.body
        else:
            continue
        for statement in body:  # the docstring, and the attribute docstrings after assignments
            if isinstance(statement, ast.Expr) and isinstance(statement.value, ast.Constant) \
                    and isinstance(statement.value.value, str):
                found.add(id(statement.value))
    return found


def vendor_names(source: str) -> list[str]:
    """The vendor or family names the code (not its comments or docstrings) holds."""
    tree = ast.parse(source)
    prose = _docstrings(tree)
    words: list[str] = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in prose:
            words.append(node.value)
        elif isinstance(node, ast.Name):
            words.append(node.id)
        elif isinstance(node, ast.Attribute):
            words.append(node.attr)
        elif isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
            words.append(node.name)
        elif isinstance(node, ast.arg):
            words.append(node.arg)
        elif isinstance(node, ast.alias):
            words.append(node.asname or node.name)
        elif isinstance(node, ast.keyword) and node.arg:
            words.append(node.arg)
    return [match.group(0) for word in words for match in VENDOR.finditer(word)]


def offences() -> dict[str, list[str]]:
    found = {}
    for scope in SCOPES:
        for path in sorted((PACKAGE / scope).rglob("*.py")):
            module = path.relative_to(PACKAGE).as_posix()
            names = vendor_names(path.read_text(encoding="utf-8"))
            if names and module not in NAMED_BEHAVIOURS:
                found[module] = names
    return found


def test_the_code_names_no_vendor_outside_the_known_exceptions() -> None:
    new = {module: dict(Counter(names)) for module, names in offences().items()
           if len(names) > KNOWN_EXCEPTIONS.get(module, 0)}
    assert not new, ("vendor or family names in code (device behaviour belongs in the profile's sections, "
                     f"device/*.py + device_profiles/*.json): {new}")


def test_the_known_exceptions_are_still_needed() -> None:
    found = offences()
    done = sorted(module for module in KNOWN_EXCEPTIONS if module not in found)
    assert not done, f"no vendor names left in {done}: remove them from KNOWN_EXCEPTIONS"


@pytest.mark.parametrize(("code", "names"), [
    ('if profile.family == "lenze-8400":\n    pass\n', ["lenze", "8400"]),
    ("MM4_ORDER = {}\n", ["MM4"]),
    ("if self.is_8400:\n    FAULT_8400 = WORDS_EMF\n", ["8400", "8400", "EMF"]),
    ("def _siemens_index(x):\n    return x\n", ["siemens"]),
    ('text = f"{node} on the 8400 motec"\n', ["8400", "motec"]),
    ('"""The 8400 motec manual, ch. 9.1."""\n# Lenze SDO2\nx = 0x640  # MICROMASTER\n', []),
    ('gateway = "ETG.8200"\nEMCY = 0x80\n', []),
])
def test_the_grep_finds_vendor_names_in_code_but_not_in_prose(code: str, names: list[str]) -> None:
    assert vendor_names(code) == names
