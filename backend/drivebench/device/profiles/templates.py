"""Message templates in device profiles (``switches.node_parameter.invalid``, ``commands.save.done``,
``control.jog.text`` …): checked when a profile loads, so formatting one later can neither fail nor grow.

A template names the fields its place gives (``{code}``, ``{value}``), each at most with a conversion (``!s``,
``!r``) and a format spec of its own: fill, alignment, sign, ``#``, ``0``, width, grouping, precision and type
(``{value:g}``, ``{bits:02X}``). Width and precision are at most ``MAX_WIDTH``: ``{value:>1000000000}`` would make
a gigabyte of text from one request. No attribute or index access (``{value.__class__}``), no positional or nested
fields. Each field is then formatted once with a value of the type it will get, so ``{code:d}`` on a text is refused
now rather than failing a request later.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from string import Formatter

from drivebench.i18n import N_, Text

MAX_WIDTH = 16
_SPEC = re.compile(r"(?:.?[<>=^])?[-+ ]?z?#?0?(?P<width>\d*)[,_]?(?:\.(?P<precision>\d+))?[bcdeEfFgGnosxX%]?",
                   re.DOTALL)


def check_template(text: str, samples: Mapping[str, object], where: str) -> None:
    """Raise ``ValueError`` (in words, naming ``where``) unless ``text`` is a template as the module says, for the
    fields ``samples`` names (with a value of the type each will have)."""
    try:
        parsed = list(Formatter().parse(text))
    except ValueError as exc:
        raise _refused(where, text, Text(N_("it is not a template ({error}); write a brace as {{{{ or }}}}"),
                                         error=str(exc))) from None
    for _literal, name, spec, conversion in parsed:
        if name is None:
            continue
        field = "{" + name + (f"!{conversion}" if conversion else "") + (f":{spec}" if spec else "") + "}"
        if name not in samples:
            raise _refused(where, text, Text(N_("{field} is not one of its fields ({allowed})"), field=field,
                                             allowed=", ".join("{" + n + "}" for n in sorted(samples))))
        if conversion not in (None, "s", "r"):
            raise _refused(where, text, Text(N_("{field}: the conversion !{conversion} is not allowed (!s, !r are)"),
                                             field=field, conversion=conversion))
        if "{" in (spec or ""):
            raise _refused(where, text, Text(N_("{field}: a nested field in a format spec is not allowed"),
                                             field=field))
        match = _SPEC.fullmatch(spec or "")
        if match is None:
            raise _refused(where, text, Text(N_("{field}: the format spec is not one this template takes"),
                                             field=field))
        for part, value in ((N_("width"), match["width"]), (N_("precision"), match["precision"])):
            if value and int(value) > MAX_WIDTH:
                raise _refused(where, text, Text(N_("{field}: the {part} {value} is more than {most}"),
                                                 field=field, part=Text(part), value=int(value), most=MAX_WIDTH))
        try:
            Formatter().format_field(Formatter().convert_field(samples[name], conversion), spec or "")
        except (ValueError, TypeError):
            raise _refused(where, text, Text(N_("{field} does not fit its value (a {kind})"), field=field,
                                             kind=_kind(samples[name]))) from None


def _kind(value: object) -> Text:
    if isinstance(value, str):
        return Text(N_("text"))
    return Text(N_("whole number") if isinstance(value, int) else N_("number"))


def _refused(where: str, text: str, why: Text) -> ValueError:
    return ValueError(Text(N_("{where} {text}: {why}"), where=where, text=repr(text[:80]), why=why))
