"""One value of an uploaded EDS edited in place on its Profiles page, in a real browser (issue 34): a value that
does not fit the object's type is refused in words and stores nothing; one that fits changes only its key in the
downloaded EDS. The German page says the same in German."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest

from drivebench.config import settings
from drivebench.web.app import create_app
from tests.conftest import screenshot, serve_app
from tests.device.lossless_corpus import LOSSLESS_FILES
from tests.device.test_eds_rewrite import assert_only_key_changed

expect = pytest.importorskip("playwright.sync_api").expect

WAIT_MS = 20_000
CASE = "comments-blank-lines-inline"


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    """A server without a plant whose uploads go to a temporary directory."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(settings, "user_profiles_dir", tmp_path_factory.mktemp("user-profiles"))
        with serve_app(create_app()) as base_url:
            yield base_url


def uploaded(page: Any, base: str, name: str) -> tuple[str, bytes]:
    _, content, _ = next(f for f in LOSSLESS_FILES if CASE in f[0])
    response = page.request.post(f"{base}/api/profiles",
                                 multipart={"file": {"name": f"{name}.eds", "mimeType": "text/plain",
                                                     "buffer": content}})
    assert response.status == 201, response.text()
    return response.json()["id"], content


def open_speed_limit(page: Any, base: str, profile_id: str) -> Any:
    page.goto(f"{base}/profiles/{profile_id}")
    page.locator("#entry-q").press_sequentially("0x2000", delay=30)
    row = page.locator("#entries tr.entry").first
    expect(row).to_contain_text("0x2000", timeout=WAIT_MS)
    expect(page.locator("#entries tr.entry")).to_have_count(1, timeout=WAIT_MS)
    row.click()
    form = page.locator("form.object-edit").first
    expect(form).to_be_visible(timeout=WAIT_MS)
    return form


def test_an_uploaded_eds_value_is_edited_in_place_and_only_its_key_changes(server: str, page: Any) -> None:
    profile_id, content = uploaded(page, server, "edit-in-place")
    form = open_speed_limit(page, server, profile_id)
    expect(form.locator("input[name=value]")).to_have_value("3000")

    form.locator("input[name=value]").fill("fast")
    form.get_by_role("button", name="Save in the file").click()
    refusal = form.locator(".object-edit-result")
    expect(refusal).to_contain_text("is not a", timeout=WAIT_MS)
    expect(refusal).to_contain_text("UNSIGNED32")
    assert page.request.get(f"{server}/api/profiles/{profile_id}/eds").body() == content  # nothing stored

    form.locator("input[name=value]").fill("3500")
    form.get_by_role("button", name="Save in the file").click()
    expect(form.locator(".object-edit-result")).to_contain_text("DefaultValue is now 3500", timeout=WAIT_MS)
    expect(page.locator("#entries tr.entry").first.locator("td").nth(7)).to_have_text("3500")
    screenshot(page, "profile-edit-in-place")
    after = page.request.get(f"{server}/api/profiles/{profile_id}/eds").body()
    assert_only_key_changed(content, after, f"{profile_id}.eds", "2000", "DefaultValue")

    form.locator("select[name=field]").select_option("max")
    form.locator("input[name=value]").fill("99999999999")
    form.get_by_role("button", name="Save in the file").click()
    expect(form.locator(".object-edit-result")).to_contain_text("is not a", timeout=WAIT_MS)
    assert page.request.get(f"{server}/api/profiles/{profile_id}/eds").body() == after


def test_the_edit_form_speaks_german_and_built_in_profiles_have_none(server: str, page: Any) -> None:
    profile_id, _ = uploaded(page, server, "edit-in-place-de")
    page.goto(f"{server}/profiles")
    page.locator("#lang-de").click()
    expect(page.locator("html")).to_have_attribute("lang", "de", timeout=WAIT_MS)
    form = open_speed_limit(page, server, profile_id)
    expect(form).to_contain_text("In der Datei ändern")
    form.locator("input[name=value]").fill("schnell")
    form.get_by_role("button", name="In der Datei speichern").click()
    expect(form.locator(".object-edit-result")).to_contain_text("kein", timeout=WAIT_MS)
    form.locator("input[name=value]").fill("3200")
    form.get_by_role("button", name="In der Datei speichern").click()
    expect(form.locator(".object-edit-result")).to_contain_text("DefaultValue ist jetzt 3200", timeout=WAIT_MS)

    page.goto(f"{server}/profiles/generic-cia402-servo")
    page.locator("#entries tr.entry").first.click()
    expect(page.locator("#entries tr.entry-detail").first).to_be_visible(timeout=WAIT_MS)
    expect(page.locator("form.object-edit")).to_have_count(0)
