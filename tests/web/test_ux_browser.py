"""The UX bar on every screen, in a real browser at 1440 x 900 against the live demo plant.

Per screen: its own page title, the current screen marked in the one navigation bar, no console errors or
uncaught exceptions, no sideways scroll, nothing fetched from outside the server (fully offline). Error pages
(unknown session, node, profile, URL) are pages of the app with a way back. Screenshots land in test-artifacts/.
"""

from __future__ import annotations

import re
from typing import Any
from urllib.parse import unquote_plus

import pytest

from tests.conftest import screenshot

SETTLE_MS = 10_000
NODE = "/sessions/demo-plant/nodes/{}?tab={}"

# (screenshot name, path, words the <title> starts with, navigation entry marked)
SCREENS = [
    ("plant", "/", "Plant", "Plant"),
    *[(f"node-{node}-{tab}", NODE.format(node, tab), f"Node {node} ·", "Plant")
      for node in (3, 5, 12) for tab in ("info", "diagnostics")],
    *[(f"node-{node}-{tab}", NODE.format(node, tab), f"Node {node} ·", "Plant")
      for node, tab in ((5, "parameters"), (3, "pdo"), (5, "pdo"), (12, "pdo"), (3, "control"), (12, "control"))],
    ("monitor", "/monitor", "Monitor", "Monitor"),
    ("scope", "/scope", "Scope", "Scope"),
    ("tools", "/tools", "Tools", "Tools"),
    ("line-project", "/line-projects", "Line project", "Line project"),
    ("profiles", "/profiles", "Profiles", "Profiles"),
    ("profile-detail", "/profiles/lenze-8400-motec-canopen", "Inverter Drives 8400 motec", "Profiles"),
    ("parameter-sets", "/parameter-sets", "Parameter sets", "Parameter sets"),
    ("remote", "/remote", "Remote", "Remote"),
]

ERRORS = [
    ("error-session", "/sessions/no-such-session/nodes/3", "Not found", "Plant: sessions and nodes"),
    ("error-node", "/sessions/demo-plant/nodes/99", "Not found", "Plant: sessions and nodes"),
    ("error-tab", "/sessions/demo-plant/nodes/3?tab=nonsense", "Not found", "Plant: sessions and nodes"),
    ("error-profile", "/profiles/no-such-profile", "Unknown device profile", "All profiles"),
    ("error-url", "/no/such/page", "Page not found", "Plant"),
    ("error-address", "/sessions/demo-plant/nodes/1001", "Invalid request", "Plant: sessions and nodes"),
]


class Watch:
    """What a page did that the UX bar forbids: console errors, uncaught exceptions, requests off the server."""

    def __init__(self, page: Any, origin: str) -> None:
        self.problems: list[str] = []
        self.origin = origin
        page.on("console", self._console)
        page.on("pageerror", lambda exc: self.problems.append(f"uncaught: {exc}"))
        page.on("request", self._request)

    def _console(self, message: Any) -> None:
        if message.type == "error":
            self.problems.append(f"console: {message.text} at {message.location.get('url', '')}")

    def _request(self, request: Any) -> None:
        url = request.url
        same_server = url.startswith(self.origin) or url.startswith(self.origin.replace("http", "ws", 1))
        if not same_server and not url.startswith(("data:", "blob:")):
            self.problems.append(f"outside request: {url}")


def settle(page: Any) -> None:
    """Waits until htmx has no request in flight (the pages load parts after the first paint)."""
    page.wait_for_load_state("load")
    page.wait_for_function("() => !document.querySelector('.htmx-request')", timeout=SETTLE_MS)
    page.wait_for_timeout(300)  # one more frame of websocket swaps


def overflow(page: Any) -> int:
    return int(page.evaluate("() => document.documentElement.scrollWidth - document.documentElement.clientWidth"))


@pytest.mark.parametrize(("name", "path", "title", "nav"), SCREENS, ids=[s[0] for s in SCREENS])
def test_screen_meets_the_ux_bar(live_server: str, page: Any, name: str, path: str, title: str, nav: str) -> None:
    watch = Watch(page, live_server)
    response = page.goto(live_server + path)
    assert response is not None and response.status == 200
    settle(page)
    screenshot(page, f"ux-{name}")

    assert page.title().startswith(title) and page.title().endswith("· DriveBench"), page.title()
    assert page.locator("header nav").count() == 1
    marked = page.locator("header nav a[aria-current=page]")
    assert marked.count() == 1 and marked.inner_text() == nav
    assert overflow(page) <= 0, f"{name} scrolls sideways by {overflow(page)} px at 1440 px"
    assert watch.problems == []


@pytest.mark.parametrize(("name", "path", "title", "way_back"), ERRORS, ids=[e[0] for e in ERRORS])
def test_error_page_is_a_page_of_the_app(live_server: str, page: Any, name: str, path: str, title: str,
                                         way_back: str) -> None:
    watch = Watch(page, live_server)
    response = page.goto(live_server + path)
    assert response is not None and response.status == (422 if name == "error-address" else 404)
    assert response.headers["content-type"].startswith("text/html")
    screenshot(page, f"ux-{name}")

    assert page.title() == f"{title} · DriveBench"
    assert page.locator("header nav a").count() == 8  # the navigation bar is there (Plant ... Scope ... Remote)
    assert page.locator(".error-page h1").inner_text() == title
    link = page.locator(".error-page a", has_text=way_back)
    link.click()
    page.wait_for_load_state("load")
    assert page.locator(".error-page").count() == 0  # the link led to a working screen
    # the document's own status is the only resource error a browser reports on such a page
    assert [p for p in watch.problems if f"status of {response.status}" not in p] == []


def test_api_clients_still_get_problem_json(live_server: str, page: Any) -> None:
    answer = page.request.get(live_server + "/sessions/demo-plant/nodes/99", headers={"Accept": "application/json"})
    assert answer.status == 404
    assert answer.headers["content-type"] == "application/problem+json"
    assert answer.json()["detail"].startswith("Node 99 is not part of session")


def test_every_control_is_reachable_by_keyboard_with_visible_focus(live_server: str, page: Any) -> None:
    """Tab from the top of the Plant page: the skip link first, then the navigation, each with a focus ring."""
    page.goto(live_server + "/")
    settle(page)
    page.keyboard.press("Tab")
    assert page.evaluate("() => document.activeElement.className") == "skip-link"
    assert page.locator(".skip-link").bounding_box()["y"] >= 0  # shown while focused
    page.keyboard.press("Tab")
    page.keyboard.press("Tab")  # brand, then the first navigation entry
    focused = page.evaluate("""() => { const e = document.activeElement;
        return {text: e.textContent.trim(), outline: getComputedStyle(e).outlineStyle}; }""")
    assert focused == {"text": "Plant", "outline": "solid"}


def test_keyboard_focus_survives_the_live_plant_table(live_server: str, page: Any) -> None:
    """The node table is pushed over the websocket twice a second; a focused NMT button must stay focused."""
    page.goto(live_server + "/")
    settle(page)
    button = page.locator("#nmt-demo-plant-5-pre-operational")
    button.focus()
    page.evaluate("() => { document.querySelector('#node-demo-plant-5').dataset.seen = 'yes'; }")
    page.wait_for_function("() => !document.querySelector('#node-demo-plant-5').dataset.seen",
                           timeout=SETTLE_MS)  # the row was replaced by a newer one
    assert page.evaluate("() => document.activeElement.id") == "nmt-demo-plant-5-pre-operational"


def test_dip_switch_keeps_focus_after_toggling_by_keyboard(live_server: str, page: Any) -> None:
    page.goto(live_server + "/tools")
    settle(page)
    page.locator("#dip-switch-6").focus()  # 8400 motec: c b a 64 32 16 -> the switch worth 16
    page.keyboard.press("Space")
    page.wait_for_function("() => document.querySelector('#dip-node-id').value === '16'", timeout=SETTLE_MS)
    assert page.evaluate("() => document.activeElement.id") == "dip-switch-6"


def test_guarding_form_keeps_what_the_user_types_while_health_refreshes(live_server: str, page: Any) -> None:
    page.goto(live_server + "/sessions/demo-plant/nodes/12?tab=diagnostics")
    settle(page)
    field = page.locator("input[name=guard_time_ms]")
    field.fill("250")
    page.evaluate("() => { document.querySelector('#diag-health-live').dataset.seen = 'yes'; }")
    page.wait_for_function("() => !document.querySelector('#diag-health-live').dataset.seen",
                           timeout=SETTLE_MS)  # the health facts were refreshed
    assert field.input_value() == "250"
    assert page.evaluate("() => document.activeElement.name") == "guard_time_ms"


def test_diagnostics_report_downloads_with_its_date(live_server: str, page: Any) -> None:
    """The report goes into a service ticket: a file, with the full date it was made, every node in it."""
    answer = page.request.get(live_server + "/api/sessions/demo-plant/diagnostics/report")
    assert answer.status == 200
    assert answer.headers["content-disposition"].startswith("attachment;")
    text = answer.text()
    assert re.search(r"created \d{4}-\d{2}-\d{2} \d{2}:\d{2}:\d{2}", text)
    assert all(name in text for name in ("Pump (MICROMASTER 440)", "Conveyor (8400 motec)", "Fan (8200 vector"))


def test_share_link_view_is_read_only_and_clean(live_server: str, browser: Any) -> None:
    """The view a share link opens: its own title, no navigation into the engineer's screens, no console errors;
    a link that is not valid is explained in a page of the app."""
    engineer = browser.new_context(viewport={"width": 1440, "height": 900})
    created = engineer.request.post(live_server + "/api/share-links", data={"ttl_minutes": 10, "label": "UX test"})
    assert created.status == 201, created.text()
    url = created.json()["url"]
    engineer.close()
    viewer = browser.new_context(viewport={"width": 1440, "height": 900})
    try:
        page = viewer.new_page()
        watch = Watch(page, live_server)
        page.goto(url)
        settle(page)
        screenshot(page, "ux-remote-view")
        assert page.title() == "Remote diagnostics · DriveBench"
        assert page.locator("header nav").count() == 0
        health = page.locator("#remote-health").inner_text()
        assert all(name in health for name in ("Pump (MICROMASTER 440)", "Conveyor (8400 motec)", "Fan (8200 vector"))
        assert overflow(page) <= 0 and watch.problems == []
        bad = page.goto(live_server + "/remote/dbv_not-a-link")
        assert bad is not None and bad.status == 401
        assert page.locator(".error-page h1").inner_text() == "Not signed in"
        assert page.locator("header nav").count() == 0
    finally:
        viewer.close()


NARROW = ["/", "/tools", "/profiles", "/profiles/lenze-8200-vector-emf2178ib", "/remote", "/monitor",
          NODE.format(12, "info"), NODE.format(12, "diagnostics"), NODE.format(12, "parameters"),
          NODE.format(3, "control"), "/parameter-sets"]
CLIPPED = """(selector) => [...document.querySelectorAll(selector)]
    .filter(cell => cell.scrollWidth > cell.clientWidth + 1).map(cell => cell.innerText)"""

TABLES_PAST_THEIR_CARD = """(selector) => [...document.querySelectorAll(selector)].filter(table => {
    const card = table.closest('.card'), style = getComputedStyle(card);
    return table.getBoundingClientRect().right > card.getBoundingClientRect().right - parseFloat(style.paddingRight)
      - parseFloat(style.borderRightWidth) + 1;
  }).map(table => table.closest('.card').querySelector('h2')?.textContent)"""


@pytest.mark.parametrize("width", [1280, 1440])
def test_monitor_shows_long_device_names_whole(live_server: str, browser: Any, width: int) -> None:
    context = browser.new_context(viewport={"width": width, "height": 900})
    try:
        page = context.new_page()
        page.goto(live_server + "/monitor")
        fan = page.locator("#nodes-body td.device", has_text="Fan (8200 vector + EMF2178IB)")
        fan.wait_for(timeout=SETTLE_MS)  # its heartbeats put node 12 in the table
        assert fan.inner_text() == "Fan (8200 vector + EMF2178IB)"
        assert fan.get_attribute("title") == "Fan (8200 vector + EMF2178IB)"
        assert page.evaluate(CLIPPED, "#nodes-body td") == []
        assert page.evaluate(TABLES_PAST_THEIR_CARD, ".counter-grid table") == []
        screenshot(page, f"ux-monitor-{width}")
    finally:
        context.close()


WRAPPED = """(selector) => [...document.querySelectorAll(selector)].filter((e) => {
    const range = document.createRange(); range.selectNodeContents(e);
    return new Set([...range.getClientRects()].map((r) => Math.round(r.top))).size > 1;
  }).map((e) => e.textContent)"""
"""The texts of ``selector`` that the browser broke over more than one line."""


@pytest.mark.parametrize("language", ["en", "de"])
def test_scope_channel_codes_and_units_are_not_broken_over_lines(live_server: str, browser: Any,
                                                                 language: str) -> None:
    """The MICROMASTER's channel offer at 1440 px: a code ("r0037") and a unit ("[°C]") stay whole beside a long
    name (they were broken as "r00 / 37" and "[° / C]")."""
    context = browser.new_context(viewport={"width": 1440, "height": 900}, locale=language,
                                  extra_http_headers={"Accept-Language": language})
    try:
        page = context.new_page()
        page.goto(live_server + "/scope/demo-plant")
        page.select_option("#channel-node", "3")
        page.locator("#channel-offer li", has_text="r0037").first.wait_for(timeout=SETTLE_MS)
        assert page.locator("#channel-offer .unit", has_text="°C").count() >= 1
        assert page.evaluate(WRAPPED, "#channel-offer .ref, #channel-offer .unit") == []
        screenshot(page, f"ux-scope-offer-{language}")
    finally:
        context.close()


def test_screens_fit_1280_px_and_plant_cells_are_not_clipped(live_server: str, browser: Any) -> None:
    context = browser.new_context(viewport={"width": 1280, "height": 800})
    try:
        page = context.new_page()
        for path in NARROW:
            page.goto(live_server + path)
            settle(page)
            assert overflow(page) <= 0, f"{path} scrolls sideways by {overflow(page)} px at 1280 px"
        page.goto(live_server + "/")
        settle(page)
        screenshot(page, "ux-plant-1280")
        clipped = page.evaluate("""() => [...document.querySelectorAll('table.nodes td')]
            .filter(td => td.scrollWidth > td.clientWidth).map(td => td.innerText)""")
        assert clipped == []  # device names and the four NMT buttons fit their columns
    finally:
        context.close()


# (page, its live field, what was typed, the request it makes, what that request carries)
LIVE_FIELDS = [
    ("/profiles/lenze-8400-motec-canopen", "#entry-q", "C00088", "/profiles/lenze-8400-motec-canopen/entries?",
     "q=C00088"),
    ("/parameter-sets", "input.audit-filter", "no such write", "/parameter-sets/audit/rows?", "q=no such write"),
    ("/tools", "#dip-node-id", "17", "/ui/tools/dip", "node_id=17"),
]


@pytest.mark.parametrize(("path", "field", "typed", "request_part", "carried"), LIVE_FIELDS)
def test_what_is_typed_while_the_page_loads_is_sent(live_server: str, page: Any, path: str, field: str, typed: str,
                                                    request_part: str, carried: str) -> None:
    """The page's scripts held back on the wire (a slow network, a busy machine): what the user typed before htmx
    set up the field is sent once the page is ready, not ignored."""
    held: list[Any] = []
    page.route("**/static/app.js", lambda route: held.append(route))
    page.goto(live_server + path, wait_until="commit")
    page.fill(field, typed)
    assert len(held) == 1
    with page.expect_request(lambda request: request_part in request.url and
                             carried in unquote_plus(request.url + "&" + (request.post_data or "")), timeout=SETTLE_MS):
        held[0].continue_()
