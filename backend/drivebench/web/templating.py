"""The Jinja2 environment for pages and their fragments (jinja2-fragments renders one block of a page)."""

from __future__ import annotations

import time

from jinja2_fragments.fastapi import Jinja2Blocks

from drivebench import i18n
from drivebench.config import settings

templates = Jinja2Blocks(directory=str(settings.frontend_dir / "templates"))
# Texts of the pages through gettext ({% trans %}, _()): the functions read the request's language (web/language).
templates.env.add_extension("jinja2.ext.i18n")
templates.env.policies["ext.i18n.trimmed"] = True  # babel.cfg extracts with trimmed = true too
templates.env.install_gettext_callables(i18n.gettext, i18n.ngettext, newstyle=True)  # type: ignore[attr-defined]
templates.env.globals["current_locale"] = i18n.current
templates.env.globals["locales"] = i18n.LOCALES


def _age(seconds: float | None) -> str:
    if seconds is None:
        return "–"
    if seconds < 10:
        return f"{seconds * 1000:.0f} ms" if seconds < 1 else f"{seconds:.1f} s"
    if seconds < 120:
        return f"{seconds:.0f} s"
    return f"{seconds / 60:.0f} min"


def _clock(timestamp: float | None) -> str:
    return time.strftime("%H:%M:%S", time.localtime(timestamp)) if timestamp else "–"


templates.env.filters["age"] = _age
templates.env.filters["number"] = i18n.number
templates.env.filters["clock"] = _clock
templates.env.filters["datetime"] = lambda ts: time.strftime("%Y-%m-%d %H:%M:%S %Z", time.localtime(ts)) if ts else "–"
templates.env.filters["hex4"] = lambda v: f"0x{v:04X}"
templates.env.filters["hex8"] = lambda v: f"0x{v:08X}"
