"""Signing in in a real browser: a viewer sees write controls greyed out with the role they need, and the server
refuses a forced write in words; an engineer writes a parameter; an admin manages users and tokens.

Its own server and its own database (users are never created in the shared test database)."""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from drivebench.config import settings
from drivebench.services.storage import database
from drivebench.services.users import accounts
from drivebench.services.users.principals import Role
from drivebench.web.app import create_app
from tests.conftest import DEMO_PLANT, fresh_channel, screenshot, serve_app

expect = pytest.importorskip("playwright.sync_api").expect

WAIT_MS = 15_000
PASSWORDS = {"root": "root password", "eve": "engineer password", "vera": "viewer password"}
NODE = "/sessions/demo-plant/nodes/5"


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    folder: Path = tmp_path_factory.mktemp("access")
    url = f"sqlite:///{folder / 'access.db'}"
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(settings, "database_url", url)
        patch.setattr(settings, "secret_key_file", folder / "secret_key")
        database.upgrade_to_head(url)
        for name, role in [("root", Role.ADMIN), ("eve", Role.ENGINEER), ("vera", Role.VIEWER)]:
            accounts.create_user(name, PASSWORDS[name], role)
        app = create_app(plant_file=DEMO_PLANT, plant_bus=f"virtual:{fresh_channel()}@500000", latency="0ms")
        with serve_app(app) as base_url:
            yield base_url
        database.dispose(url)


def sign_in(page: Any, base_url: str, name: str, target: str = NODE) -> None:
    page.goto(base_url + target)
    expect(page).to_have_url(re.compile(r"/login\?next="), timeout=WAIT_MS)
    page.get_by_label("User name").fill(name)
    page.get_by_label("Password").fill(PASSWORDS[name])
    page.get_by_role("button", name="Sign in").click()
    expect(page).to_have_url(base_url + target, timeout=WAIT_MS)
    expect(page.locator(".signed-in .who")).to_contain_text(name)


def _row(page: Any, ref: str) -> Any:
    return page.locator(f"tr[data-ref='{ref}']")


def _search(page: Any, text: str) -> None:
    page.fill("#param-q", text)
    expect(page.locator("#param-rows")).to_have_attribute("data-count", "1", timeout=WAIT_MS)


def test_login_page_and_a_wrong_password(server: str, page: Any) -> None:
    page.goto(server + "/")
    expect(page).to_have_url(re.compile(r"/login"), timeout=WAIT_MS)
    page.get_by_label("User name").fill("vera")
    page.get_by_label("Password").fill("not her password")
    page.get_by_role("button", name="Sign in").click()
    expect(page.locator(".login-card .error")).to_contain_text("Wrong user name or password.", timeout=WAIT_MS)
    screenshot(page, "access-login-refused")


def test_viewer_cannot_write_engineer_can(server: str, page: Any, browser: Any) -> None:
    sign_in(page, server, "vera")
    expect(page.locator("body")).to_have_attribute("data-role", "viewer")
    _search(page, "rated motor current")
    row = _row(page, "C00088")
    row.get_by_role("button", name="Read").click()  # reading is a viewer's right
    expect(_row(page, "C00088").locator("td.val")).to_contain_text("10.20 A", timeout=WAIT_MS)
    write = _row(page, "C00088").get_by_role("button", name="Write")
    expect(write).to_be_disabled()
    expect(write).to_have_attribute("title", "Writing parameters needs the engineer role.")
    screenshot(page, "access-viewer-node")
    # The grey button is only a courtesy: forced anyway, the server refuses in words, beside the field.
    write.evaluate("button => { button.disabled = false; button.closest('tr').querySelectorAll('[disabled]')"
                   ".forEach(e => e.disabled = false); }")
    _row(page, "C00088").locator("input[name=value]").fill("12.5")
    write.click()
    expect(_row(page, "C00088")).to_contain_text(
        "Writing parameters needs the engineer role; you are signed in as vera (viewer).", timeout=WAIT_MS)
    screenshot(page, "access-viewer-refused")
    # The Control tab: a viewer watches the drive live (state, actual values) but its controls are refused.
    page.goto(f"{server}/sessions/demo-plant/nodes/3?tab=control")
    expect(page.locator("#ctl-ws")).to_have_text("live", timeout=WAIT_MS)
    expect(page.locator("#ctl-refused")).to_contain_text(
        "Controlling a drive needs the engineer role; you are signed in as vera (viewer)")
    expect(page.locator("#ctl-actuals canvas").first).to_be_visible(timeout=WAIT_MS)
    expect(page.locator("[data-command=switch_on]")).to_be_disabled()
    expect(page.locator("[data-command=quick_stop]")).to_be_disabled()
    expect(page.locator("[data-jog='1']")).to_be_disabled()
    screenshot(page, "access-viewer-control")

    page.locator(".signed-in").get_by_role("button", name="Sign out").click()
    expect(page).to_have_url(re.compile(r"/login$"), timeout=WAIT_MS)

    sign_in(page, server, "eve")
    _search(page, "rated motor current")
    _row(page, "C00088").locator("input[name=value]").fill("12.5")
    _row(page, "C00088").get_by_role("button", name="Write").click()
    expect(_row(page, "C00088").locator("td.val")).to_contain_text("12.50 A", timeout=WAIT_MS)
    expect(page.get_by_role("link", name="Users")).to_have_count(0)  # an engineer manages no users
    # scripts of the page (control.js, monitor.js) use fetch: app.js adds the session's CSRF token to it
    status = page.evaluate("fetch('/api/sessions/demo-plant/monitor/pause', {method: 'POST'}).then(r => r.status)")
    assert status == 200
    screenshot(page, "access-engineer-wrote")


def test_admin_adds_a_user_and_creates_a_token_shown_once(server: str, page: Any) -> None:
    sign_in(page, server, "root", "/users")
    form = page.locator("#users-block form").first
    form.get_by_label("Name").fill("otto")
    form.get_by_label("Role").select_option("engineer")
    form.get_by_label("Password").fill("otto password")
    form.get_by_label("Again").fill("otto password")
    form.get_by_role("button", name="Add user").click()
    expect(page.locator("#users-block .ok")).to_contain_text("Added otto (engineer).", timeout=WAIT_MS)
    tokens = page.locator("#tokens-block form").first
    tokens.get_by_label("Token name").fill("nightly backup")
    tokens.get_by_label("User").select_option("otto")
    tokens.get_by_label("Role").select_option("viewer")
    tokens.get_by_role("button", name="Create token").click()
    secret = page.locator("#tokens-block .token-secret")
    expect(secret).to_have_value(re.compile(r"^dbt_"), timeout=WAIT_MS)
    expect(page.locator("#tokens-block table")).to_contain_text("nightly backup")
    screenshot(page, "access-users")
    page.reload()
    expect(page.locator("#tokens-block .token-secret")).to_have_count(0)  # shown once
