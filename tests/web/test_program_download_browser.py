"""Program download in a real browser (issue 32 step 3): on node 7's Info tab a HEX file is picked and checked, Download
asks the confirmation dialog naming the node and the file, the progress bar fills with bytes, rate and ETA from the job
websocket, and the result shows the new software identification (0x1F56) the simulated drive computes from the
image. The confirmation says what a download does (no keep-alive holds it), and the node's lease is this tab's (program
download)."""

from __future__ import annotations

import os
import zlib
from pathlib import Path
from typing import Any

import pytest
from playwright.sync_api import expect

from drivebench.simulator.plant import Plant
from tests.conftest import screenshot
from tests.web.firmware_files import intel_hex

pytestmark = pytest.mark.browser

SERVO = 7
TIMEOUT_MS = 60_000


def test_a_hex_file_is_downloaded_with_progress_and_the_new_identification_shown(
        demo_server: tuple[str, Plant], page: Any, tmp_path: Path) -> None:
    base, plant = demo_server
    image = os.urandom(120_000)
    firmware = tmp_path / "axis-2.1.hex"
    firmware.write_bytes(intel_hex(image))
    page.goto(f"{base}/sessions/demo-plant/nodes/{SERVO}?tab=info")
    card = page.locator("#firmware-card")
    expect(card).to_be_visible(timeout=TIMEOUT_MS)
    card.locator("#firmware-file").set_input_files(str(firmware))
    card.get_by_role("button", name="Check file").click()
    expect(card.locator("#firmware-check")).to_contain_text(f"Intel HEX, {len(image)} bytes", timeout=TIMEOUT_MS)
    card.locator("#firmware-download").click()

    dialog = page.locator("#moving-confirm")
    expect(dialog).to_be_visible(timeout=TIMEOUT_MS)
    expect(dialog.locator(".moving-confirm-text")).to_contain_text(f"node {SERVO}")
    expect(dialog.locator(".moving-confirm-values")).to_contain_text(f"axis-2.1.hex ({len(image)} bytes")
    assert plant.nodes[SERVO].program.downloads == 0, "asked only: nothing sent before the confirmation"
    note = dialog.locator(".moving-confirm-note")  # issue 32: a download's own words, not the keep-alive's
    expect(note).to_contain_text("The download goes on when this page closes")
    expect(note).not_to_contain_text("keeps the node alive")
    dialog.locator("button[value=ok]").click()

    progress = card.locator("#firmware-progress")
    expect(progress).to_be_visible(timeout=TIMEOUT_MS)
    expect(progress.locator(".firmware-figures")).to_contain_text("KiB/s", timeout=TIMEOUT_MS)
    outcome = card.locator("#firmware-outcome")
    expect(outcome).to_contain_text("Program downloaded and started", timeout=TIMEOUT_MS)
    expect(outcome).to_contain_text(f"0x{zlib.crc32(image):08X}")
    assert progress.locator("progress").evaluate("bar => bar.value === bar.max")
    expect(progress.locator(".firmware-figures")).to_contain_text(f"{len(image) / 1024:.1f} KiB of")
    screenshot(page, "program-download-done")
    # issue 32: the download's lease is this tab's (its panel id: the banner says "you"), named after the download,
    # not "the API" of any client on this host
    expect(page.locator("#lease-slot")).to_contain_text(
        f"You hold the write lease of node {SERVO} (program download API)", timeout=TIMEOUT_MS)
    assert plant.nodes[SERVO].program.image == image
