"""The Profiles screen in a real browser: list, one profile, live search, 'show more', upload errors, delete.

Read-only flows and the refused upload (which stores nothing) use the shared ``live_server``; the upload that is
stored runs on a server of its own whose registry keeps uploads in a temporary directory.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from drivebench.config import REPO_ROOT, settings
from drivebench.web.app import create_app
from tests.conftest import screenshot, serve_app

expect = pytest.importorskip("playwright.sync_api").expect

SERVO_EDS = REPO_ROOT / "tests" / "data" / "eds" / "cia402_servo.eds"
MOTEC = "lenze-8400-motec-canopen"
WAIT_MS = 15_000

LAYOUT_PROBLEMS = """() => {
  const problems = [];
  if (document.documentElement.scrollWidth > window.innerWidth) problems.push("page scrolls sideways");
  for (const table of document.querySelectorAll("table")) {
    if (table.scrollWidth > table.parentElement.clientWidth + 1) problems.push("table wider than its card");
  }
  for (const cell of document.querySelectorAll("td, h1")) {
    if (cell.closest("[hidden]") || cell.scrollWidth <= cell.clientWidth + 1) continue;
    const text = cell.textContent.trim().replace(/\\s+/g, " ");
    const title = (cell.title || cell.closest("[title]")?.title || "").replace(/\\s+/g, " ");
    const ellipsis = getComputedStyle(cell).textOverflow === "ellipsis";
    if (!ellipsis || !title) problems.push("clipped without ellipsis and tooltip: " + text);
  }
  return problems;
}"""


BROKEN_AT_START = "zz-broken.json"


@pytest.fixture(scope="module")
def own_server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[str, Path, Any]]:
    """A server without a plant whose uploads go to a temporary directory (which holds one bad file already)."""
    user_dir = tmp_path_factory.mktemp("user-profiles")
    (user_dir / BROKEN_AT_START).write_text('{\n  "id": "zz-broken",\n  "family": oops\n}\n')
    app = create_app()
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(settings, "user_profiles_dir", user_dir)
        with serve_app(app) as base_url:
            yield base_url, user_dir, app


def assert_fits(page: Any) -> None:
    assert page.evaluate(LAYOUT_PROBLEMS) == []


def test_list_open_motec_and_search_c00088(live_server: str, page: Any) -> None:
    page.goto(f"{live_server}/profiles")
    row = page.locator(f"#profile-{MOTEC}")
    expect(row).to_contain_text("Lenze")
    expect(row).to_contain_text("built in")
    motec = json.loads((REPO_ROOT / "device_profiles" / f"{MOTEC}.json").read_text())
    expect(row.locator("td").nth(5)).to_have_text(str(len(motec["objects"])))
    expect(row.locator("td").nth(6)).to_have_text(str(len(motec["parameters"])))
    assert_fits(page)
    screenshot(page, "profiles-list")

    row.get_by_role("link").first.click()
    expect(page.locator("h1")).to_contain_text("8400 motec")
    expect(page.locator("#entries tr.entry")).to_have_count(100)
    page.locator("#entry-q").press_sequentially("C00088", delay=30)
    hits = page.locator("#entries tr.entry")
    expect(hits).to_have_count(1, timeout=WAIT_MS)
    cells = hits.first.locator("td")
    expect(cells.nth(0)).to_have_text("C00088")
    expect(cells.nth(3)).to_have_text("Rated motor current")
    expect(cells.nth(6)).to_have_text("A")
    expect(cells.nth(7)).to_have_text("10.20")
    assert page.url.endswith(f"/profiles/{MOTEC}?q=C00088")
    hits.first.click()
    expect(page.locator("#entries tr.entry-detail").first).to_contain_text("UNSIGNED32; raw = value × 100")
    assert_fits(page)
    screenshot(page, "profiles-motec-c00088")


def test_search_by_index_and_number_and_show_more(live_server: str, page: Any) -> None:
    page.goto(f"{live_server}/profiles/lenze-93xx-emf2178ib")
    rows = page.locator("#entries tr.entry")
    expect(rows).to_have_count(100)
    total = int(page.locator(".entries-count strong").inner_text())
    assert total > 200
    page.get_by_role("button", name="Show 100 more").click()
    expect(rows).to_have_count(200, timeout=WAIT_MS)
    assert_fits(page)
    screenshot(page, "profiles-93xx-show-more")

    page.goto(f"{live_server}/profiles/{MOTEC}")
    page.locator("#entry-q").press_sequentially("0x5FA7", delay=30)
    expect(page.locator("#entries tr.entry").first.locator("td").nth(0)).to_have_text("C00088", timeout=WAIT_MS)
    page.locator("#entry-q").fill("")
    page.locator("#entry-q").press_sequentially("88", delay=30)
    expect(page.locator("#entries tr.entry").first.locator("td").nth(3)).to_have_text("Rated motor current",
                                                                                      timeout=WAIT_MS)
    page.locator("#entry-kind").select_option("objects")
    expect(page.locator(".entries-count")).to_contain_text("match", timeout=WAIT_MS)
    expect(page.locator("#entries tr.entry.parameter")).to_have_count(0, timeout=WAIT_MS)


def test_bad_upload_shows_file_line_and_reason_and_keeps_the_list(live_server: str, page: Any) -> None:
    page.goto(f"{live_server}/profiles")
    before = page.locator("table.profiles tbody tr").count()
    lines = SERVO_EDS.read_bytes().split(b"\n")[:51]  # no object section: refused
    lines[40] = b"\x00\x01\x02PK\x03\x04"
    page.set_input_files("input[name=file]", files=[
        {"name": "broken.eds", "mimeType": "application/octet-stream", "buffer": b"\n".join(lines)}])
    page.get_by_role("button", name="Upload").click()
    error = page.locator("#upload-result .error")
    expect(error).to_contain_text("broken.eds", timeout=WAIT_MS)
    expect(error).to_contain_text("line 41")
    expect(error).to_contain_text("binary junk")
    expect(error).to_contain_text("Nothing was stored")
    expect(page.locator("table.profiles tbody tr")).to_have_count(before)
    assert_fits(page)
    screenshot(page, "profiles-bad-upload")


def uploads(user_dir: Path) -> list[str]:
    return sorted(p.name for p in user_dir.iterdir() if p.name != BROKEN_AT_START)


def test_files_that_did_not_load_are_listed_with_line_and_reason(own_server: tuple[str, Path, Any], page: Any
                                                                 ) -> None:
    base, _, _ = own_server
    page.goto(f"{base}/profiles")
    row = page.locator("#load-errors tbody tr")
    expect(row).to_have_count(1)
    expect(row.locator("td").nth(0)).to_have_text(BROKEN_AT_START)
    expect(row.locator("td").nth(1)).to_have_text("3")
    expect(row.locator("td").nth(2)).to_contain_text("not valid JSON")
    expect(page.locator("table.profiles tbody tr")).not_to_have_count(0)
    assert_fits(page)
    screenshot(page, "profiles-load-errors")


def test_too_large_upload_is_refused_beside_the_form(own_server: tuple[str, Path, Any], page: Any) -> None:
    base, user_dir, app = own_server
    registry = app.state.drivebench.registry
    limit, registry.max_upload_bytes = registry.max_upload_bytes, 4096
    try:
        page.goto(f"{base}/profiles")
        page.set_input_files("input[name=file]", str(SERVO_EDS))
        page.get_by_role("button", name="Upload").click()
        error = page.locator("#upload-result .error")
        expect(error).to_contain_text("Upload too large", timeout=WAIT_MS)
        expect(error).to_contain_text("4 KiB")
    finally:
        registry.max_upload_bytes = limit
    assert uploads(user_dir) == []


def test_upload_open_and_delete(own_server: tuple[str, Path, Any], page: Any) -> None:
    base, user_dir, _ = own_server
    page.goto(f"{base}/profiles")
    page.set_input_files("input[name=file]", str(SERVO_EDS))
    page.get_by_role("button", name="Upload").click()
    expect(page.locator("#upload-result .ok")).to_contain_text("Loaded", timeout=WAIT_MS)
    uploaded = page.locator("table.profiles tbody tr", has_text="EM-Servo 400")
    expect(uploaded).to_contain_text("uploaded")
    assert len(uploads(user_dir)) == 1
    assert_fits(page)
    screenshot(page, "profiles-uploaded")

    uploaded.get_by_role("link", name="EM-Servo 400").click()
    page.locator("#entry-q").press_sequentially("controlword", delay=30)
    expect(page.locator("#entries tr.entry").first).to_contain_text("0x6040", timeout=WAIT_MS)
    page.goto(f"{base}/profiles")
    asked: list[str] = []
    page.once("dialog", lambda dialog: (asked.append(dialog.message), dialog.accept()))
    # each step of the path waited for and named (this failed once under load, not reproduced since): the question
    # asked and accepted, the request sent and answered, then the list with the message swapped in
    with page.expect_response(lambda answer: answer.url.endswith("/delete"), timeout=WAIT_MS) as deleting:
        page.locator("table.profiles tbody tr", has_text="EM-Servo 400").get_by_role("button", name="Delete").click()
    assert asked, "the Delete button asked no question"
    assert deleting.value.status == 200, f"{deleting.value.status}: {deleting.value.text()[:500]}"
    try:
        expect(page.locator("#upload-result .ok")).to_contain_text("Deleted", timeout=WAIT_MS)
    except AssertionError as exc:
        raise AssertionError(f"{exc}\nthe page shows: {page.locator('#profiles-body').inner_text()[:400]}") from exc
    expect(page.locator("table.profiles tbody tr", has_text="EM-Servo 400")).to_have_count(0)
    assert uploads(user_dir) == []


def test_a_pasted_code_is_searched_without_a_key_press(live_server: str, page: Any) -> None:
    """Pasting (or autocompleting) a code fires no key event; the search must run on the input itself."""
    page.goto(f"{live_server}/profiles/siemens-micromaster4-canopen")
    expect(page.locator("#entries tr.entry")).to_have_count(100)
    page.locator("#entry-q").fill("P2010")
    hits = page.locator("#entries tr.entry")
    expect(hits).to_have_count(1, timeout=WAIT_MS)
    expect(hits.first.locator("td").nth(2)).to_have_text("0x27DA.0")
    expect(hits.first.locator("td").nth(3)).to_have_text("CANopen baud rate")


def quirky_servo() -> bytes:
    """The corpus base with several quirks at once: limits repaired and dropped, no ProductName, a wrong count."""
    from tests.device.quirk_corpus import BASE, LIMITS, STRUCTURE
    text = BASE
    for case in (LIMITS[0], LIMITS[1], LIMITS[2], STRUCTURE[2], STRUCTURE[4]):
        text = case.quirk(text)
    return text.replace("ProductName=Servo 400", "ProductName=Quirky Servo 400").encode()


def test_import_warnings_are_shown_in_the_list_the_profile_and_its_rows(own_server: tuple[str, Path, Any],
                                                                        page: Any) -> None:
    base, _, _ = own_server
    page.goto(f"{base}/profiles")
    page.set_input_files("input[name=file]", files=[
        {"name": "quirky_servo.eds", "mimeType": "application/octet-stream", "buffer": quirky_servo()}])
    page.get_by_role("button", name="Upload", exact=True).click()
    loaded = page.locator("#upload-result .ok")
    expect(loaded).to_contain_text("Loaded quirky_servo with 5 warnings", timeout=WAIT_MS)
    row = page.locator("#profile-quirky_servo")
    expect(row.locator(".warn-count")).to_have_text("5 warnings")
    assert_fits(page)
    screenshot(page, "profiles-list-warning-badge")

    row.locator(".warn-count").click()
    warnings = page.locator("#import-warnings")
    expect(warnings).to_be_visible(timeout=WAIT_MS)
    expect(warnings.locator(".badge.warn").first).to_have_text("5")
    expect(warnings.locator("tbody tr")).to_have_count(5)
    dropped = warnings.locator("tbody tr.limits", has_text="limits dropped: LowLimit 0x80000000 > HighLimit")
    expect(dropped.locator("td").nth(2)).to_have_text("0x2000sub0")
    expect(warnings).to_contain_text("read as 65535")
    expect(warnings).to_contain_text("SupportedObjects=6 but [ManufacturerObjects] lists 4")
    page.locator("#entry-q").press_sequentially("0x2000", delay=30)
    speed = page.locator("#entries tr.entry").first
    expect(speed.locator(".badge.limits")).to_have_text("limits", timeout=WAIT_MS)
    speed.click()
    expect(page.locator("#entries tr.entry-detail").first).to_contain_text("repaired or dropped on import")
    assert_fits(page)
    screenshot(page, "profiles-import-warnings")


def test_a_zip_of_several_files_gives_a_summary_table(own_server: tuple[str, Path, Any], page: Any) -> None:
    import io
    import zipfile

    from tests.device.quirk_corpus import CORPUS_FILES
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w") as archive:
        for name, content, _ in CORPUS_FILES[:6]:
            archive.writestr(f"Vendor/{name}", content)
        archive.writestr("Vendor/empty.eds", b"[FileInfo]\nFileName=empty.eds\n")
    base, _, _ = own_server
    page.goto(f"{base}/profiles")
    page.set_input_files("input[name=files]", files=[
        {"name": "vendor.zip", "mimeType": "application/zip", "buffer": buffer.getvalue()}])
    page.get_by_role("button", name="Load all files").click()
    summary = page.locator("#batch-result")
    expect(summary).to_contain_text("7 files", timeout=WAIT_MS)
    expect(summary).to_contain_text("6 with warnings")
    expect(summary).to_contain_text("1 refused")
    expect(summary.locator("tr.refused")).to_contain_text("no object dictionary")
    assert_fits(page)
    screenshot(page, "profiles-batch-summary")
