"""The Jinja2 environment for pages and their fragments (jinja2-fragments renders one block of a page)."""

from __future__ import annotations

import functools
import time
from typing import Any

from jinja2_fragments.fastapi import Jinja2Blocks
from starlette.requests import Request

from drivebench import i18n
from drivebench.config import settings
from drivebench.device.profiles.number_base import shows_hex
from drivebench.i18n import N_
from drivebench.web.root import root_of, route_path


def _root(request: Request) -> dict[str, Any]:
    """``root``: the sub-path the browser reaches the server under (web/root.py), in front of every URL a page has."""
    return {"root": root_of(request.scope)}


templates = Jinja2Blocks(directory=str(settings.frontend_dir / "templates"), context_processors=[_root])
templates.env.globals["root"] = ""  # a page rendered without a request (the diagnostics report) links nowhere
templates.env.filters["route_path"] = route_path  # a request's path without the sub-path (the `next` of a link)
# Texts of the pages through gettext ({% trans %}, _()): the functions read the request's language (web/language).
templates.env.add_extension("jinja2.ext.i18n")
templates.env.policies["ext.i18n.trimmed"] = True  # babel.cfg extracts with trimmed = true too
templates.env.install_gettext_callables(i18n.gettext, i18n.ngettext, newstyle=True)  # type: ignore[attr-defined]
templates.env.globals["current_locale"] = i18n.current
templates.env.globals["locales"] = i18n.LOCALES


@functools.cache
def _script_texts() -> tuple[str, ...]:
    """The texts the page scripts mark with _("…"), found once by Babel's JavaScript extractor (as pybabel does)."""
    from babel.messages.extract import extract_from_file  # at the first page: not a cost of the start

    found: set[str] = set()
    for script in sorted((settings.frontend_dir / "static").glob("*.js")):
        found.update(message for _line, message, _comments, _context in extract_from_file("javascript", str(script))
                     if isinstance(message, str))
    return tuple(sorted(found))


def _script_messages() -> dict[str, str]:
    """The scripts' texts in the request's language, for the page's <script type="application/json">."""
    return {text: i18n.gettext(text) for text in _script_texts()}


templates.env.globals["script_messages"] = _script_messages


def _age(seconds: float | None) -> str:
    if seconds is None:
        return "–"
    if seconds < 10:
        return f"{i18n.number(seconds * 1000, 0)} ms" if seconds < 1 else f"{i18n.number(seconds, 1)} s"
    if seconds < 120:
        return f"{i18n.number(seconds, 0)} s"
    return f"{i18n.number(seconds / 60, 0)} min"


def _shown(value: Any, item: Any) -> str:
    """A value read from a node as its row shows it: a number with its unit in the request's language
    (``1.234,5 V`` in German); selections, bit words, text and hex bytes, and every value in English, as the service
    formats them (``display``, which the JSON API sends too)."""
    number, entry = value.value, item.entry
    if (i18n.current() == i18n.DEFAULT or not isinstance(number, int | float) or isinstance(number, bool)
            or entry.selection or entry.bits or shows_hex(item)):
        return str(value.display)
    decimals = entry.decimals if entry.factor != 1 else 0
    text = i18n.number(number, decimals if 0 < decimals <= 2 else None)  # FIX32 (4 decimals) keeps what it has
    return f"{text} {entry.unit}" if entry.unit else text


def _clock(timestamp: float | None) -> str:
    return time.strftime("%H:%M:%S", time.localtime(timestamp)) if timestamp else "–"


# The states services.bus_state reports, marked for the catalogue; the pages show them through the filter.
BUS_STATES = (N_("active"), N_("warning"), N_("passive"), N_("bus-off"), N_("adapter lost"))
templates.env.filters["bus_state"] = lambda state: i18n.gettext(state) if state in BUS_STATES else state
templates.env.filters["age"] = _age
# What the audit log stores in English (its origin and the details DriveBench writes), shown in the reader's language.
AUDIT_WORDS = (N_("parameters"), N_("commissioning"), N_("control"), N_("pdo"), N_("diagnostics"), N_("read-all"),
               N_("upload"), N_("undo"), N_("not read back"), N_("takes effect after reset node"),
               N_("cancelled while the write was under way: the device may hold either value"))
SET_JOB_KINDS = ("download", "retry", "rollback", "undo")  # "<kind> <download id>" (set_jobs.py), "undo <record id>"


def _audit_words(text: str | None) -> str | None:
    if not text or text in AUDIT_WORDS or text in SET_JOB_KINDS:  # a set job's reading before it has an id
        return i18n.gettext(text) if text else text
    kind, _, number = text.partition(" ")
    return f"{i18n.gettext(kind)} {number}" if kind in SET_JOB_KINDS and number.isdigit() else text


templates.env.filters["audit_words"] = _audit_words
templates.env.filters["number"] = i18n.number
templates.env.filters["shown"] = _shown
templates.env.filters["shown_text"] = i18n.shown
templates.env.filters["clock"] = _clock
templates.env.filters["datetime"] = lambda ts: time.strftime("%Y-%m-%d %H:%M:%S %Z", time.localtime(ts)) if ts else "–"
templates.env.filters["hex4"] = lambda v: f"0x{v:04X}"
templates.env.filters["hex8"] = lambda v: f"0x{v:08X}"
