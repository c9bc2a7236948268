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

NAMED_BEHAVIOURS: dict[str, int] = {
    # the state-machine kinds a control section selects: cia402 / lenze / none
    "services/control/drive_words.py": 1,
    "device/drive/control.py": 1,
    # the addressing kinds a profile names (lenze_code / siemens_mm4): the schema's literals and their defaults
    "device/profiles/profile.py": 6,
    # the simulator's drive models a control section's ``simulation`` names (lenze_8400 / lenze_emf2178ib)
    "simulator/lenze_control.py": 4,
}
"""Modules that hold the table of named behaviours a profile selects by name, with how many family names each holds
(the keys of that table, nothing else)."""

CITING_TEXTS: dict[str, int] = {
    # the manual's worked example, shown as a given of the cable calculator: "Lenze repeater type 2176"
    "device/calculators/cable.py": 1,
    # the errors of the code range and of the parameter channel name the device whose manual sets the rule
    "device/profiles/addressing.py": 2,
}
"""User texts that cite a manual by its device (prose a user reads, not a branch), with how many names each holds."""

KNOWN_EXCEPTIONS: dict[str, int] = {}
"""Modules that still name a vendor, with how many names each may hold: the numbers only go down."""


def allowed(module: str) -> int:
    return NAMED_BEHAVIOURS.get(module, 0) + CITING_TEXTS.get(module, 0) + KNOWN_EXCEPTIONS.get(module, 0)


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
            if names:
                found[module] = names
    return found


def test_the_code_names_no_vendor_outside_the_known_exceptions() -> None:
    new = {module: dict(Counter(names)) for module, names in offences().items()
           if len(names) > allowed(module)}
    assert not new, ("vendor or family names in code (device behaviour belongs in the profile's sections, "
                     f"device/*.py + device_profiles/*.json): {new}")


def test_the_allowed_counts_are_exact() -> None:
    found = offences()
    fewer = {module: len(found.get(module, [])) for module in {*NAMED_BEHAVIOURS, *CITING_TEXTS, *KNOWN_EXCEPTIONS}
             if len(found.get(module, [])) < allowed(module)}
    assert not fewer, f"fewer vendor names than allowed (lower the counts, remove a module at 0): {fewer}"


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
