"""The Parameter sets screen in a real browser, on a server of its own (demo plant on a fresh virtual bus,
temporary database): upload node 5, export the set as JSON, change it, import it (first with a value out of
range: the line is named), compare the node with the changed set, download it (preview -> report), roll back,
and find the writes in the audit log."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from tests.conftest import screenshot
from tests.web.conftest import demo_server_with_own_db

expect = pytest.importorskip("playwright.sync_api").expect

WAIT_MS = 20_000
LAYOUT_PROBLEMS = """() => {
  const problems = [];
  if (document.documentElement.scrollWidth > window.innerWidth) problems.push("page scrolls sideways");
  for (const table of document.querySelectorAll("table")) {
    if (table.offsetParent && table.scrollWidth > table.parentElement.clientWidth + 1)
      problems.push("table wider than its box: " + (table.className || table.id));
  }
  return problems;
}"""


@pytest.fixture(scope="module")
def sets_server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    with demo_server_with_own_db(tmp_path_factory, "sets-db") as base_url:
        yield base_url


def import_file(page: Any, path: Path, name: str) -> None:
    form = page.locator("#import-card form")
    form.locator("input[type=file]").set_input_files(str(path))
    form.locator("input[name=name]").fill(name)
    form.get_by_role("button", name="Import").click()


def test_export_change_compare_download(page: Any, sets_server: str, tmp_path: Path) -> None:
    page.goto(f"{sets_server}/parameter-sets")
    # every field has a label; the file input reads like the one on the Profiles page
    assert page.get_by_label("JSON, CSV or DCF file").get_attribute("type") == "file"
    assert page.locator("#audit").get_by_label("Filter").get_attribute("name") == "q"
    assert page.evaluate(LAYOUT_PROBLEMS) == []
    screenshot(page, "sets-empty")
    upload = page.locator("#upload-card form")
    upload.locator("select[name=target]").select_option("demo-plant:5")
    upload.locator("input[name=name]").fill("Conveyor as found")
    upload.get_by_role("button", name="Upload all parameters").click()
    expect(page.locator("#upload-result .ok")).to_contain_text("Stored as set", timeout=WAIT_MS)
    expect(page.locator("#set-list")).to_contain_text("Conveyor as found", timeout=WAIT_MS)

    page.locator("#set-list a", has_text="Conveyor as found").click()
    expect(page.locator("#set-detail h2")).to_have_text("Conveyor as found", timeout=WAIT_MS)
    with page.expect_download() as download_info:
        page.get_by_role("link", name="Export JSON").click()
    exported = json.loads(Path(download_info.value.path()).read_text())
    assert exported["profile_id"] == "lenze-8400-motec-canopen"

    # change: one value out of range first - the import names its line and stores nothing
    for parameter in exported["parameters"]:
        if parameter["ref"] == "C00088":
            parameter["value"] = 12.5
        if parameter["ref"] == "C00324/1":
            parameter["value"] = 9999
    bad = tmp_path / "conveyor-bad.json"
    bad.write_text(json.dumps(exported, indent=1))
    import_file(page, bad, "Conveyor commissioned")
    errors = page.locator("#import-result .line-errors")
    expect(errors).to_contain_text("C00324/1", timeout=WAIT_MS)
    expect(errors).to_contain_text("6500")
    screenshot(page, "sets-import-errors")

    next(p for p in exported["parameters"] if p["ref"] == "C00324/1")["value"] = 0
    good = tmp_path / "conveyor.json"
    good.write_text(json.dumps(exported, indent=1))
    import_file(page, good, "Conveyor commissioned")
    expect(page.locator("#import-result .ok")).to_contain_text("Imported as", timeout=WAIT_MS)
    href = page.locator("#import-result .ok a").get_attribute("href")
    new_id = href.rsplit("=", 1)[1]

    # compare the node with the changed set: only C00088, scaled with its unit
    expect(page.locator(f"#compare-form select[name=right] option[value='set:{new_id}']")).to_have_count(
        1, timeout=WAIT_MS)
    compare = page.locator("#compare-form")
    compare.locator("select[name=left]").select_option("node:demo-plant:5")
    compare.locator("select[name=right]").select_option(f"set:{new_id}")
    compare.get_by_role("button", name="Compare").click()
    rows = page.locator("#compare-result .compare-table tbody tr")
    expect(rows).to_have_count(1, timeout=WAIT_MS)
    expect(rows.first).to_contain_text("C00088")
    expect(rows.first).to_contain_text("10.20 A")
    expect(rows.first).to_contain_text("12.50 A")
    page.locator("#compare").scroll_into_view_if_needed()
    screenshot(page, "sets-compare")

    # download: preview -> report -> roll back
    page.locator("#import-result .ok a").click()
    expect(page.locator("#set-detail h2")).to_have_text("Conveyor commissioned", timeout=WAIT_MS)
    page.locator("#set-detail").get_by_role("button", name="Preview changes").click()
    preview = page.locator("#download-area .preview")
    expect(preview).to_contain_text("1 of", timeout=WAIT_MS)
    expect(preview.locator("tbody tr")).to_have_count(1)
    expect(preview).to_contain_text("12.50 A")
    screenshot(page, "sets-preview")
    preview.get_by_role("button", name="Download 1 changes").click()
    # the set holds C00007 (control mode, a command source), but node 5 holds its value already: the download
    # writes only C00088, nothing that moves, so nothing is asked
    report = page.locator("#download-area .report")
    expect(report).to_have_attribute("data-state", "done", timeout=WAIT_MS)
    expect(report.locator(".report-table tbody tr")).to_have_count(1)
    expect(report.locator(".report-table")).to_contain_text("written")
    expect(report).to_contain_text("parameters unchanged")
    expect(page.locator("#set-downloads")).to_contain_text("done", timeout=WAIT_MS)  # the set's download list
    expect(page.locator("#audit .audit-table")).to_contain_text("12.50 A", timeout=WAIT_MS)  # and the audit log
    assert page.evaluate(LAYOUT_PROBLEMS) == []
    screenshot(page, "sets-download-report")

    page.once("dialog", lambda dialog: dialog.accept())
    report.get_by_role("button", name="Roll back").click()
    rolled = page.locator("#download-area .report")
    expect(rolled).to_contain_text("Rollback", timeout=WAIT_MS)
    expect(rolled).to_have_attribute("data-state", "done", timeout=WAIT_MS)
    expect(rolled.locator(".report-table")).to_contain_text("10.20 A")

    page.reload()
    audit = page.locator("#audit .audit-table tbody")
    # the rollback, the download's write, and the download switching on the node's SDO2 (0x1201 sub 1 and 2) to
    # read what the node held first (issue 28 item 4: every write the tool sends is in the audit log)
    expect(audit.locator("tr")).to_have_count(4, timeout=WAIT_MS)
    expect(audit.locator("tr").first).to_contain_text("rollback")
    expect(audit.locator("tr").nth(1)).to_contain_text("12.50 A")
    expect(audit.locator("tr").nth(2)).to_contain_text("0x1201")
    expect(audit.locator("tr").nth(3)).to_contain_text("0x1201")
    page.locator("#audit").scroll_into_view_if_needed()
    assert page.evaluate(LAYOUT_PROBLEMS) == []
    screenshot(page, "sets-audit")


def test_download_dialog_names_exactly_the_moving_values_it_changes(page: Any, sets_server: str) -> None:
    """Issue 28 item 2: node 12's set with C0001 (setpoint source: can move the drive), C0012 and C0039 changed.
    The dialog lists C0001 only (not the unchanged moving values of the set); Cancel writes nothing and leaves no
    error behind."""
    api = page.request
    started = api.post(f"{sets_server}/api/parameter-sets/upload",
                       data={"session_id": "demo-plant", "node_id": 12, "name": "Fan as found"})
    assert started.ok, started.text()
    job = started.json()
    for _ in range(400):
        if job["state"] != "running":
            break
        page.wait_for_timeout(100)
        job = api.get(f"{sets_server}/api/parameter-sets/jobs/{job['id']}").json()
    assert job["state"] == "done", job
    set_id = job["set_id"]
    changed = api.patch(f"{sets_server}/api/parameter-sets/{set_id}",
                        data={"name": "Fan commissioned", "values": {"C0001": 1, "C0012": 7.5, "C0039": 35}})
    assert changed.ok, changed.text()

    page.goto(f"{sets_server}/parameter-sets?set={set_id}")
    expect(page.locator("#set-detail h2")).to_have_text("Fan commissioned", timeout=WAIT_MS)
    page.locator("#set-detail select[name=target]").first.select_option("demo-plant:12")
    page.locator("#set-detail").get_by_role("button", name="Preview changes").click()
    preview = page.locator("#download-area .preview")
    expect(preview.locator("tbody tr")).to_have_count(3, timeout=WAIT_MS)
    download = preview.get_by_role("button", name="Download 3 changes")
    # a red message of an earlier try beside the button (where the page shows this form's errors)
    page.evaluate("""(button) => {
      const box = document.createElement("div");
      box.className = "error earlier-try";
      box.textContent = "Node 12 did not answer";
      errorSlot(button.closest("form")).append(box);
    }""", download.element_handle())
    expect(page.locator(".earlier-try")).to_have_count(1)
    download.click()
    asked = page.locator("#moving-confirm")
    expect(asked).to_be_visible(timeout=WAIT_MS)
    expect(asked).to_contain_text("Sends to node 12")
    values = asked.locator(".moving-confirm-values li")
    expect(values).to_have_count(1)
    expect(values.first).to_contain_text("C0001")
    screenshot(page, "sets-download-asks-changed-only")
    asked.get_by_role("button", name="Cancel").click()
    expect(asked).to_be_hidden(timeout=WAIT_MS)
    expect(page.locator(".earlier-try")).to_have_count(0)
    expect(page.locator("#download-area .error")).to_have_count(0)
    expect(page.locator("#toast .error")).to_have_count(0)
    expect(preview).to_be_visible()
    value = api.get(f"{sets_server}/api/sessions/demo-plant/nodes/12/parameters/C0012").json()
    assert value["display"] != "7.50 s"  # nothing was written
