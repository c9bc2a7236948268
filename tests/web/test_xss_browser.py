"""Stored XSS and framing (issue 16 items 2, 5, 8) in a real browser.

Profiles with script in every text field (a JSON profile made from the MICROMASTER's with every name, unit,
selection text, bit name, group, description, note, emergency text and identity string carrying a payload, and
an EDS with payloads in its names, units, descriptions, vendor/product and comments) are uploaded through the API
and put on simulated nodes of the plant under a node name with a payload; a lease holder named by a payload holds a
node. Every page and every node tab is opened: no dialog, no payload runs, and the Content-Security-Policy the app
sends is never violated by its own pages. A page on another port cannot frame the app.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest
from fastapi import FastAPI

from drivebench.config import REPO_ROOT, settings
from drivebench.web.app import create_app
from tests.conftest import DEMO_PLANT, fresh_channel, screenshot, serve_app, wait_until

pytestmark = pytest.mark.browser
expect = pytest.importorskip("playwright.sync_api").expect

# Breaks out of an attribute (either quote), runs through an event handler and through a script element.
PAYLOAD = "\"'><img src=x onerror=__xss=1,alert(1)><script>__xss=2</script>"
JSON_NODE, EDS_NODE = 20, 21
WAIT_MS = 15_000
TEXT_KEYS = {"name", "unit", "description", "object_name", "denotation", "subcode_name", "group", "vendor_name",
             "product_name", "source", "text", "remedy", "vendor_error"}
TEXT_LISTS = {"groups", "notes", "order_codes"}
TEXT_MAPS = {"selection", "bits"}

# Records what a CSP blocks (the browser also logs it; the event carries the directive) before any page script.
WATCH_CSP = """
window.__csp = [];
document.addEventListener("securitypolicyviolation",
  (e) => window.__csp.push(`${e.violatedDirective} ${e.blockedURI} ${e.sourceFile}:${e.lineNumber}`));
"""


def poisoned(value: Any, key: str = "") -> Any:
    """Every text field of a profile with the payload appended (ids, codes and types stay as they are)."""
    if isinstance(value, dict):
        if key in TEXT_MAPS:
            return {k: f"{v} {PAYLOAD}" for k, v in value.items()}
        return {k: poisoned(v, k) for k, v in value.items()}
    if isinstance(value, list):
        return [f"{v} {PAYLOAD}" if key in TEXT_LISTS else poisoned(v, key) for v in value]
    if isinstance(value, str) and key in TEXT_KEYS:
        return f"{value} {PAYLOAD}"
    return value


def poisoned_json_profile() -> bytes:
    profile = json.loads((REPO_ROOT / "device_profiles" / "siemens-micromaster4-canopen.json").read_text())
    profile = poisoned(profile)
    profile["id"] = "xss-micromaster"
    # a switch block of its own (a key or alias another profile's block uses is refused), its texts poisoned too
    profile["switches"].update(key="xss-switches", aliases=[], name=f"XSS switches {PAYLOAD}",
                               short_name=f"XSS {PAYLOAD}")
    profile["notes"].append(PAYLOAD)
    return json.dumps(profile).encode()


def poisoned_eds() -> bytes:
    """The hand-written CiA 402 servo EDS with payloads in names, descriptions, units, identity and comments."""
    lines = []
    for line in (REPO_ROOT / "tests" / "data" / "eds" / "cia402_servo.eds").read_text().splitlines():
        key = line.split("=", 1)[0]
        if key in ("ParameterName", "VendorName", "ProductName", "Description", "Line1", "Line2"):
            line = f"{line} {PAYLOAD}"
        lines.append(line)
        if key == "PDOMapping" and line.endswith("=1"):  # every PDO-mappable object gets a unit with script
            lines += [f"Unit={PAYLOAD}"]
    return ("\n".join(lines) + "\n").encode()


def take_lease(base_url: str) -> None:
    """Someone named by a payload (X-DriveBench-User, no login) writes node 20 and so holds its write lease."""
    parameter = f"{base_url}/api/sessions/demo-plant/nodes/{JSON_NODE}/parameters/P2040"
    value = httpx.get(parameter, timeout=30).json()["value"]
    answer = httpx.put(parameter, json={"value": value}, timeout=30,
                       headers={"X-DriveBench-User": PAYLOAD, "X-DriveBench-Client": "someone-else"})
    assert answer.status_code == 200, answer.text


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[str, FastAPI]]:
    app = create_app(plant_file=DEMO_PLANT, plant_bus=f"virtual:{fresh_channel()}@500000", latency="0ms")
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(settings, "user_profiles_dir", tmp_path_factory.mktemp("user-profiles"))
        with serve_app(app) as base_url:
            state = app.state.drivebench
            plant = state.plants["demo-plant"]
            api = f"{base_url}/api"
            for node_id, (file_name, content) in ((JSON_NODE, ("xss.json", poisoned_json_profile())),
                                                   (EDS_NODE, ("xss.eds", poisoned_eds()))):
                answer = httpx.post(f"{api}/profiles", files={"file": (file_name, content)}, timeout=30)
                assert answer.status_code == 201, answer.text
                profile_id = answer.json()["id"]
                plant.add_node(state.registry.get(profile_id), node_id, name=f"sim {PAYLOAD}")
                answer = httpx.post(f"{api}/sessions/demo-plant/nodes", timeout=30,
                                    json={"node_id": node_id, "profile_id": profile_id, "name": PAYLOAD})
                assert answer.status_code == 201, answer.text
            take_lease(base_url)
            answer = httpx.post(f"{api}/share-links", json={"ttl_minutes": 30, "label": PAYLOAD}, timeout=30)
            assert answer.status_code == 201, answer.text
            app.state.xss_link = answer.json()["token"]  # shown once, at creation
            yield base_url, app


@pytest.fixture
def watched(page: Any) -> Iterator[tuple[Any, list[str]]]:
    """The page with its dialogs (dismissed) and its CSP complaints in the console collected."""
    complaints: list[str] = []
    page.add_init_script(WATCH_CSP)
    page.on("dialog", lambda dialog: (complaints.append(f"dialog: {dialog.message}"), dialog.dismiss()))
    page.on("console", lambda msg: complaints.append(f"console: {msg.text}")
            if "Content Security Policy" in msg.text or "Refused to" in msg.text else None)
    yield page, complaints


def assert_clean(page: Any, complaints: list[str], where: str) -> None:
    page.wait_for_load_state("load")
    found = page.evaluate("""() => ({
      xss: window.__xss === undefined ? null : String(window.__xss),
      csp: window.__csp || [],
      injected: [...document.querySelectorAll('img[src="x"], script')]
        .filter((e) => e.matches("img") || e.text.includes("__xss"))
        .map((e) => e.outerHTML.slice(0, 80) + ' in ' + (e.parentElement && e.parentElement.className)),
    })""")
    assert found == {"xss": None, "csp": [], "injected": []}, where
    assert complaints == [], where


def open_node_tabs(page: Any, complaints: list[str], base: str, node_id: int) -> None:
    for tab, ready in (("parameters", "#param-table, .param-table, table"), ("pdo", "#pdo-tab"),
                       ("diagnostics", "#main .card"), ("control", "#control-tab"), ("info", "#main .card")):
        page.goto(f"{base}/sessions/demo-plant/nodes/{node_id}?tab={tab}")
        page.locator(ready).first.wait_for(timeout=WAIT_MS)
        if tab == "pdo":
            for summary in page.locator(".pdo-card summary").all():
                summary.click()
            page.locator(".pdo-picker li button").first.wait_for(state="attached", timeout=WAIT_MS)  # names, units
        screenshot(page, f"xss-node{node_id}-{tab}")
        assert_clean(page, complaints, f"node {node_id} {tab}")


def test_payloads_in_every_profile_field_never_run(server: tuple[str, FastAPI], watched: Any) -> None:
    base, app = server
    page, complaints = watched
    for path in ("/", "/monitor/demo-plant", "/tools", "/parameter-sets", "/profiles", "/profiles/xss-micromaster",
                 "/remote"):
        page.goto(base + path)
        page.locator("#main").wait_for(timeout=WAIT_MS)
        if path.startswith("/profiles/"):
            for row in page.locator("tr.entry").all()[:20]:
                row.click()  # the details row: description, selection list, bit names
        if path.startswith("/monitor"):  # an SDO read puts node 20 (named by a payload) into the node table
            page.locator("#live-state.live").wait_for(timeout=WAIT_MS)
            httpx.get(f"{base}/api/sessions/demo-plant/nodes/{JSON_NODE}/parameters/P2040", timeout=30)
            # node 20 shows (node 21, a simulated CiA 402 servo, may show too: both device names carry payloads)
            expect(page.locator("#nodes-body tr", has_text=f"{JSON_NODE}").locator("td.device", has_text="onerror")
                   .first).to_be_visible(timeout=WAIT_MS)
        screenshot(page, "xss" + (path.replace("/", "-") if path != "/" else "-plant"))
        assert_clean(page, complaints, path)
    eds_profile = page.evaluate("fetch('/api/profiles').then((r) => r.json())")
    servo = next(p["id"] for p in eds_profile if "EM-Servo" in p["product"])
    page.goto(f"{base}/profiles/{servo}")
    page.locator("#entries tr.entry").first.wait_for(timeout=WAIT_MS)
    assert_clean(page, complaints, f"/profiles/{servo}")

    for node_id in (JSON_NODE, EDS_NODE, 3):
        open_node_tabs(page, complaints, base, node_id)

    page.goto(f"{base}/remote/{app.state.xss_link}")
    page.locator("#remote-health").wait_for(timeout=WAIT_MS)
    assert_clean(page, complaints, "remote view")


def test_lease_holder_and_problem_texts_are_shown_as_text(server: tuple[str, FastAPI], watched: Any) -> None:
    """Item 8: the 409 naming a lease holder called by a payload, on the Control tab (control.js) and as a JSON
    problem answered to an htmx request (app.js)."""
    base, _ = server
    page, complaints = watched
    page.goto(f"{base}/sessions/demo-plant/nodes/{JSON_NODE}?tab=control")
    page.locator("#ctl-ws.good").wait_for(timeout=WAIT_MS)
    take_lease(base)
    page.locator('#control-panel input[name="ctl-mode"]:not(:checked)').first.click()  # a write: refused
    error = page.locator("#ctl-result .error")
    expect(error).to_contain_text("is being written by", timeout=WAIT_MS)
    expect(error).to_contain_text(PAYLOAD)
    assert_clean(page, complaints, "control tab lease refusal")

    # htmx asking the JSON API: app.js shows the problem's title and detail next to the action
    take_lease(base)
    save = f"/api/sessions/demo-plant/nodes/{JSON_NODE}/commands/save"
    page.evaluate("(url) => htmx.ajax('POST', url, {source: '#toast'})", save)
    toast = page.locator("#toast .error")
    expect(toast).to_contain_text("Node is being written by someone else", timeout=WAIT_MS)
    expect(toast).to_contain_text(PAYLOAD)
    screenshot(page, "xss-problem-toast")
    assert_clean(page, complaints, "problem fragment in the toast")

    # The server answers htmx with an HTML fragment it escaped; app.js shows a JSON problem reaching htmx (from a
    # proxy, or a route answering JSON) itself: its title and detail must stay text as well.
    problem = {"type": "about:blank", "title": PAYLOAD, "status": 409, "detail": f"held by {PAYLOAD}"}
    page.route("**/commands/restore-defaults", lambda route: route.fulfill(
        status=409, content_type="application/problem+json", body=json.dumps(problem)))
    page.evaluate("(url) => htmx.ajax('POST', url, {source: '#toast'})", save.replace("save", "restore-defaults"))
    expect(toast).to_contain_text(f"held by {PAYLOAD}", timeout=WAIT_MS)
    expect(toast.locator("strong")).to_have_text(PAYLOAD)
    assert_clean(page, complaints, "JSON problem in the toast")


def test_a_page_elsewhere_cannot_frame_the_app(server: tuple[str, FastAPI], page: Any, tmp_path: Path) -> None:
    """Item 5: a page on another local port embeds the Plant page; the browser refuses to show it in the frame."""
    base, _ = server
    evil = FastAPI()

    @evil.get("/")
    def framing_page() -> Any:
        from fastapi.responses import HTMLResponse
        return HTMLResponse(f'<!doctype html><iframe id="app" src="{base}/" width="800" height="600"></iframe>')

    complaints: list[str] = []
    page.on("console", lambda msg: complaints.append(msg.text))
    with serve_app(evil) as evil_url:
        page.goto(evil_url)
        frame = page.frame_locator("#app")
        assert wait_until(lambda: any("frame-ancestors" in text or "X-Frame-Options" in text for text in complaints),
                          seconds=15), complaints
        assert frame.locator(".brand").count() == 0  # nothing of the app is shown inside the frame
