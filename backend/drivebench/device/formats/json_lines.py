"""Line numbers for JSON profile files: where a value sits, and which key is given twice.

The standard ``json`` module gives a line only for syntax errors; a profile that is valid JSON but not a valid
profile (a wrong data type, a duplicate key, a duplicate object) must name its line too. The walk here runs only
after a file has failed, so it favours being simple over being fast.
"""

from __future__ import annotations

import json
import math
from json.decoder import scanstring  # type: ignore[attr-defined]
from json.scanner import NUMBER_RE
from typing import Any

from drivebench.i18n import N_, Text

JsonPath = tuple[str | int, ...]
_WHITESPACE = " \t\n\r"
_LITERALS = {"true": True, "false": False, "null": None, "NaN": math.nan, "Infinity": math.inf, "-Infinity": -math.inf}


class DuplicateKey(ValueError):
    def __init__(self, key: str, line: int, first_line: int) -> None:
        super().__init__(Text(N_("duplicate key '{key}' (first at line {line})"), key=key, line=first_line))
        self.key, self.line, self.first_line = key, line, first_line


def reject_duplicate_keys(text: str | bytes) -> None:
    """Raise :class:`DuplicateKey` (with its line) if any JSON object in ``text`` names a key twice.

    Fast path: the C parser with a hook; only a file with a duplicate is walked again for the line."""
    def no_duplicates(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
        keys = [key for key, _ in pairs]
        if len(set(keys)) != len(keys):
            raise _Found
        return dict(pairs)

    try:
        json.loads(text, object_pairs_hook=no_duplicates)
    except _Found:
        try:
            _Walker(text if isinstance(text, str) else text.decode("utf-8-sig")).walk()
        except DuplicateKey:
            raise
        except ValueError:
            return  # the walker cannot follow the text: the validator reports what it finds
    except ValueError:
        return  # a syntax error: the validator reports it with its line


class _Found(Exception):
    pass


def value_lines(text: str) -> tuple[Any, dict[JsonPath, int]]:
    """Parse ``text`` into Python values and the line where each value starts (by path, the root is ``()``).

    For a value inside an object the line is that of its key. Raises ValueError for text that is no JSON and
    :class:`DuplicateKey` for a key given twice."""
    walker = _Walker(text)
    value = walker.walk()
    return value, walker.lines


def line_of(lines: dict[JsonPath, int], path: JsonPath) -> int | None:
    """The line of ``path``, or of its nearest parent that has one (pydantic paths can go deeper than the text)."""
    for end in range(len(path), -1, -1):
        found = lines.get(path[:end])
        if found is not None:
            return found
    return None


class _Walker:
    def __init__(self, text: str) -> None:
        self.text = text[1:] if text.startswith("\ufeff") else text
        self.pos = 0
        self.lines: dict[JsonPath, int] = {}

    def line(self, pos: int) -> int:
        return self.text.count("\n", 0, pos) + 1

    def skip(self) -> None:
        while self.pos < len(self.text) and self.text[self.pos] in _WHITESPACE:
            self.pos += 1

    def walk(self) -> Any:
        value = self.value((), None)
        self.skip()
        if self.pos != len(self.text):
            raise ValueError(f"extra data at line {self.line(self.pos)}")
        return value

    def value(self, path: JsonPath, line: int | None) -> Any:
        self.skip()
        self.lines[path] = line if line is not None else self.line(self.pos)
        char = self.text[self.pos:self.pos + 1]
        if char == "{":
            return self.object(path)
        if char == "[":
            return self.array(path)
        if char == '"':
            text, self.pos = scanstring(self.text, self.pos + 1)
            return text
        for word, literal in _LITERALS.items():
            if self.text.startswith(word, self.pos):
                self.pos += len(word)
                return literal
        match = NUMBER_RE.match(self.text, self.pos)
        if match is None:
            raise ValueError(f"not JSON at line {self.line(self.pos)}")
        self.pos = match.end()
        integer, fraction, exponent = match.groups()
        return float(integer + (fraction or "") + (exponent or "")) if fraction or exponent else int(integer)

    def object(self, path: JsonPath) -> dict[str, Any]:
        self.pos += 1
        result: dict[str, Any] = {}
        first_lines: dict[str, int] = {}
        self.skip()
        if self._take("}"):
            return result
        while True:
            self.skip()
            key_line = self.line(self.pos)
            if not self.text.startswith('"', self.pos):
                raise ValueError(f"expected a key at line {key_line}")
            key, self.pos = scanstring(self.text, self.pos + 1)
            if key in first_lines:
                raise DuplicateKey(key, key_line, first_lines[key])
            first_lines[key] = key_line
            self.skip()
            if not self._take(":"):
                raise ValueError(f"expected ':' at line {self.line(self.pos)}")
            result[key] = self.value((*path, key), key_line)
            if not self._more("}"):
                return result

    def array(self, path: JsonPath) -> list[Any]:
        self.pos += 1
        result: list[Any] = []
        self.skip()
        if self._take("]"):
            return result
        while True:
            result.append(self.value((*path, len(result)), None))
            if not self._more("]"):
                return result

    def _take(self, char: str) -> bool:
        """Step over ``char`` if it comes next."""
        if self.text.startswith(char, self.pos):
            self.pos += 1
            return True
        return False

    def _more(self, closer: str) -> bool:
        """After a member of an object or array: True at a ',' (another member follows), False at ``closer``."""
        self.skip()
        if self._take(","):
            return True
        if self._take(closer):
            return False
        raise ValueError(f"expected ',' or '{closer}' at line {self.line(self.pos)}")
