"""Every answer carries the Content-Security-Policy (no inline script, no framing) and the other browser security
headers (issue 16 items 2 and 5): pages, fragments, static files, the JSON API, its errors and refusals."""

from __future__ import annotations

import base64
import hashlib
import re
from html.parser import HTMLParser

import pytest
from fastapi.testclient import TestClient

from drivebench.config import REPO_ROOT, settings
from drivebench.web.app import create_app
from drivebench.web.templating import templates

PAGES = ["/", "/monitor/demo-plant", "/tools", "/parameter-sets", "/profiles", "/profiles/siemens-micromaster4-canopen",
         "/remote", "/sessions/demo-plant/nodes/3?tab=parameters", "/sessions/demo-plant/nodes/3?tab=control",
         "/sessions/demo-plant/nodes/5?tab=pdo", "/ui/sessions/demo-plant/nodes/3/tabs/control", "/no-such-page"]
API = ["/api/sessions", "/api/profiles", "/api/sessions/demo-plant/nodes/99", "/static/app.js", "/openapi.json"]


def directives(policy: str) -> dict[str, list[str]]:
    return {name: values for name, *values in (part.split() for part in policy.split(";") if part.strip())}


def assert_secure(answer, where: str) -> None:  # type: ignore[no-untyped-def]
    policy = directives(answer.headers.get("content-security-policy", ""))
    assert policy.get("default-src") == ["'self'"], where
    assert policy.get("script-src") == ["'self'"], f"{where}: scripts only from this server, none inline, no eval"
    assert policy.get("frame-ancestors") == ["'none'"], where
    assert policy.get("object-src") == ["'none'"], where
    assert "'unsafe-inline'" not in policy.get("script-src", []) and "'unsafe-eval'" not in str(policy), where
    assert answer.headers.get("x-frame-options") == "DENY", where
    assert answer.headers.get("x-content-type-options") == "nosniff", where
    assert answer.headers.get("referrer-policy") == "same-origin", where


@pytest.mark.only_reads
@pytest.mark.parametrize("path", PAGES + API)
@pytest.mark.slow  # among the costliest of the quick subset (--durations, issue 29): `make test-quick` leaves it out
def test_every_answer_carries_the_policy(client: TestClient, path: str) -> None:
    assert_secure(client.get(path), path)


def test_refusals_and_htmx_errors_carry_it_too(client: TestClient) -> None:
    refused = client.post("/api/profiles", content=b"x" * 64, headers={"Content-Length": str(2**30)})
    assert refused.status_code == 413
    assert_secure(refused, "413 before the body is read")
    problem = client.put("/api/sessions/demo-plant/nodes/3/parameters/P2040", json={"value": "many"},
                         headers={"HX-Request": "true"})
    assert problem.status_code == 422
    assert_secure(problem, "htmx error fragment")


class InlineCode(HTMLParser):
    """Collects what a browser would run from the page itself: script elements without src, on* attributes, and
    htmx attributes htmx would eval (hx-on, trigger filters, js: values)."""

    def __init__(self) -> None:
        super().__init__()
        self.found: list[str] = []

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        values = dict(attrs)
        if tag == "script" and "src" not in values and values.get("type") != "application/json":
            self.found.append("inline <script>")
        for name, value in attrs:
            if name.startswith(("on", "hx-on")):
                self.found.append(f"<{tag} {name}=...>")
            elif name.startswith("hx-") and re.search(r"^\s*(js|javascript):|\[.*\]", value or ""):
                self.found.append(f"<{tag} {name}={value!r}>")


@pytest.mark.only_reads
def test_pages_hold_no_inline_script_or_handler(client: TestClient) -> None:
    """What the policy would block is not in the pages at all (a blocked script is a feature that silently broke)."""
    for path in PAGES[:-1]:
        parser = InlineCode()
        parser.feed(client.get(path).text)
        assert parser.found == [], path


def test_templates_escape_every_value() -> None:
    assert templates.env.autoescape is True or templates.env.autoescape("page.html")  # type: ignore[operator]


def test_the_api_docs_page_runs_its_own_script_by_hash_only(monkeypatch: pytest.MonkeyPatch) -> None:
    """FastAPI's /docs (development only) has one inline script: allowed by its hash, not by 'unsafe-inline'; it
    cannot be framed."""
    monkeypatch.setattr(settings, "api_docs", True)
    with TestClient(create_app()) as client:
        answer = client.get("/docs")
    script = re.search(r"<script>(.*?)</script>", answer.text, re.DOTALL)
    assert script is not None
    digest = base64.b64encode(hashlib.sha256(script.group(1).encode()).digest()).decode()
    policy = directives(answer.headers["content-security-policy"])
    assert f"'sha256-{digest}'" in policy["script-src"] and "'unsafe-inline'" not in policy["script-src"]
    assert policy["frame-ancestors"] == ["'none'"]


def test_no_template_marks_data_as_safe() -> None:
    for template in (REPO_ROOT / "frontend" / "templates").rglob("*.html"):
        assert not re.search(r"\|\s*safe\b|Markup\(", template.read_text()), template.name
