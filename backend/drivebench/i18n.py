"""Languages of the UI: English (the source texts) and German, gettext catalogues read with Babel.

The catalogues are in ``drivebench/locale/<lang>/LC_MESSAGES/messages.po`` (inside the package, so the problem
details built in Python and the pages' templates share one catalogue that ships with the package).
``make i18n-compile`` (run by ``make install``) writes the ``.mo`` files; a catalogue whose ``.mo`` is missing or
older than its ``.po`` (a clean clone, an sdist, a ``.po`` just edited) is compiled in memory by Babel when first
used, so a German page never silently falls back to English.

The language of a request is chosen once (``negotiate``: the switch's cookie, else ``Accept-Language``, else
English) and held in a context variable for everything that request renders or raises.
"""

from __future__ import annotations

import contextlib
import functools
import gettext as gettext_module
import io
from collections.abc import Iterable, Iterator, Mapping
from contextvars import ContextVar
from decimal import Decimal
from pathlib import Path
from typing import Self

from babel import Locale, negotiate_locale
from babel.numbers import format_decimal, get_decimal_symbol
from markupsafe import escape

LOCALES = ("en", "de")
DEFAULT = "en"
DOMAIN = "messages"
LOCALE_DIR = Path(__file__).resolve().parent / "locale"
COOKIE = "drivebench_lang"

_current: ContextVar[str] = ContextVar("drivebench_locale", default=DEFAULT)


def N_(message: str) -> str:
    """Marks a text for extraction where it is defined (an error class's title); it is translated when shown."""
    return message


@functools.cache
def translations(locale: str) -> gettext_module.NullTranslations:
    if locale == DEFAULT:
        return gettext_module.NullTranslations()
    po_path = LOCALE_DIR / locale / "LC_MESSAGES" / f"{DOMAIN}.po"
    mo_path = po_path.with_suffix(".mo")
    if mo_path.exists() and mo_path.stat().st_mtime >= po_path.stat().st_mtime:
        with mo_path.open("rb") as mo_file:
            return gettext_module.GNUTranslations(mo_file)
    from babel.messages.mofile import write_mo  # only here: Babel's catalogue code is ~0.02 s of every start
    from babel.messages.pofile import read_po

    with po_path.open("rb") as po_file:
        catalog = read_po(po_file, locale=locale, domain=DOMAIN)
    compiled = io.BytesIO()
    write_mo(compiled, catalog)  # fuzzy entries are left out, as pybabel compile does
    compiled.seek(0)
    return gettext_module.GNUTranslations(compiled)


def current() -> str:
    return _current.get()


@contextlib.contextmanager
def using(locale: str) -> Iterator[None]:
    """Everything inside speaks ``locale`` (a request, a websocket connection, a test)."""
    token = _current.set(locale if locale in LOCALES else DEFAULT)
    try:
        yield
    finally:
        _current.reset(token)


def gettext(message: str) -> str:
    return translations(_current.get()).gettext(message)


def ngettext(singular: str, plural: str, n: int) -> str:
    return translations(_current.get()).ngettext(singular, plural, n)


_ = gettext


class Text(str):
    """A text kept as its N_() template and values, for one made outside a request and shown later to readers of
    any language (a warning stored with a profile, a file that did not load at start). The string itself is the
    English text; ``shown()`` puts it into the current language. Values may be Texts themselves."""

    template: str
    values: dict[str, object]
    translated = True

    def __new__(cls, template: str, /, **values: object) -> Self:
        text = super().__new__(cls, template.format(**values))
        text.template, text.values = template, values
        return text

    @classmethod
    def joined(cls, separator: str, texts: Iterable[str]) -> Self:
        """``separator.join(texts)`` that keeps each part's template."""
        values = {f"t{n}": text for n, text in enumerate(texts)}
        escaped = separator.replace("{", "{{").replace("}", "}}")
        joined = cls(escaped.join("{" + name + "}" for name in values), **values)
        joined.translated = False
        return joined

    def __reduce__(self) -> tuple[object, ...]:  # copy and pickle: str's own would format the English text again
        return _rebuilt, (type(self), self.template, self.values, self.translated)

    def shown(self) -> str:
        template = gettext(self.template) if self.translated and self.template else self.template
        return template.format(**{k: shown(v) if isinstance(v, Text) else v for k, v in self.values.items()})

    def __html__(self) -> str:
        """A template shows it in the reader's language (Jinja escapes through ``__html__``)."""
        return str(escape(self.shown()))

    def saved(self) -> dict[str, object]:
        """As JSON keeps it (a download report, a scope marker in the database); ``Text.loaded`` makes it again. A
        value JSON cannot keep (an exception, a bus spec in an error's detail) is kept in its words."""
        return {"template": self.template, "translated": self.translated,
                "values": {k: _kept(v) for k, v in self.values.items()}}

    @classmethod
    def loaded(cls, data: dict[str, object]) -> Text:
        values = data["values"]
        assert isinstance(values, dict)
        return _rebuilt(cls, str(data["template"]), {k: cls.loaded(v) if isinstance(v, dict) else v
                                                      for k, v in values.items()}, bool(data.get("translated", True)))


def _kept(value: object) -> object:
    if isinstance(value, Text):
        return value.saved()
    return value if value is None or isinstance(value, str | int | float | bool) else str(value)


def _rebuilt(cls: type[Text], template: str, values: dict[str, object], translated: bool) -> Text:
    text = cls(template, **values)
    text.translated = translated
    return text


def shown(text: str) -> str:
    """``text`` in the current language when it is a :class:`Text`; any other string as it is."""
    return text.shown() if isinstance(text, Text) else text


def accepted_languages(header: str | None) -> list[str]:
    """The languages of an ``Accept-Language`` header, most wanted first (q=0 means "not this one")."""
    weighted: list[tuple[float, int, str]] = []
    for position, part in enumerate((header or "").split(",")):
        tag, _sep, params = part.strip().partition(";")
        quality = 1.0
        for param in params.split(";"):
            key, _eq, value = param.strip().partition("=")
            if key == "q":
                try:
                    quality = float(value)
                except ValueError:
                    quality = 0.0
        if tag and tag != "*" and quality > 0:
            weighted.append((-quality, position, tag))
    return [tag for _q, _pos, tag in sorted(weighted)]


def negotiate(accept_language: str | None, cookie: str | None = None) -> str:
    """The switch's choice (cookie) wins; then the browser's languages as Babel matches them; then English."""
    if cookie in LOCALES:
        return str(cookie)
    return negotiate_locale(accepted_languages(accept_language), LOCALES, sep="-") or DEFAULT


def from_environment(environ: Mapping[str, str]) -> str:
    """The language of a command line: the first of LC_ALL, LC_MESSAGES, LANG that is set (``de_DE.UTF-8``: German;
    ``C``, ``POSIX`` or a language we do not have: English), as the C library chooses the messages' language."""
    for name in ("LC_ALL", "LC_MESSAGES", "LANG"):
        if value := environ.get(name, ""):
            language = value.split(".")[0].split("@")[0].split("_")[0].lower()
            return language if language in LOCALES else DEFAULT
    return DEFAULT


def number(value: float | int | Decimal, digits: int | None = None) -> str:
    """A number as the current language writes it: 1,234.5 in English, 1.234,5 in German. ``digits`` fixes the
    decimals shown; without it up to six are kept (a scaled parameter value keeps its resolution)."""
    locale = Locale.parse(_current.get())
    if digits is not None:
        pattern = "#,##0" + ("." + "0" * digits if digits > 0 else "")
        return format_decimal(value, format=pattern, locale=locale)
    return format_decimal(value, format="#,##0.######", locale=locale)


def decimal_symbol() -> str:
    """The decimal mark of the current language (``.`` or ``,``)."""
    return str(get_decimal_symbol(Locale.parse(_current.get())))
