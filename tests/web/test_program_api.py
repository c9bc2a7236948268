"""Program download (CiA 302-3) over the real HTTP API and job websocket on the demo plant: the file checked (Intel
HEX checksums, the product it names), the 428 without a confirmation naming the node, the image sent by block transfer
(segmented to a drive without it) and read back by 0x1F56, cancel, a flash error and a power loss mid-flash in words."""

from __future__ import annotations

import os
import zlib
from typing import Any

import httpx
import pytest
from fastapi.testclient import TestClient

from drivebench.services.program import uploads
from drivebench.web.app import create_app
from tests.confirming import confirmed
from tests.conftest import DEMO_PLANT, fresh_channel, wait_until
from tests.test_cli import free_port, poll
from tests.transport.test_multiprocess import START_TIMEOUT_S, CliProcess
from tests.web.firmware_files import broken_checksum, intel_hex

NODE = "/api/sessions/demo-plant/nodes/{node}/program"
FAULTS = "/api/sessions/demo-plant/simulator/nodes/{node}/faults"
SERVO, FAN = 7, 12


def _sim(client: TestClient, node: int) -> Any:
    return client.app.state.drivebench.plants["demo-plant"].nodes[node]  # type: ignore[attr-defined]


def _check(client: TestClient, node: int, name: str, content: bytes, identity: str | None = None) -> Any:
    data = {"identity": identity} if identity is not None else None
    return client.post(NODE.format(node=node) + "/check", files={"file": (name, content)}, data=data)


def _finished(client: TestClient | httpx.Client, node: int, job_id: str) -> dict[str, Any]:
    url = NODE.format(node=node) + f"/jobs/{job_id}"
    assert wait_until(lambda: client.get(url).json()["state"] != "running", 60)
    return client.get(url).json()


def _why(job: dict[str, Any]) -> str:
    """A finished job's state, error and result in the assertion message (pytest cuts a long dict)."""
    return f"{job['state']}: {job.get('error')}; result {job.get('result')}"


def _download(client: TestClient | httpx.Client, node: int, file_id: str) -> dict[str, Any]:
    started = confirmed(client, "POST", NODE.format(node=node) + "/download", json={"file_id": file_id})
    assert started.status_code == 202, started.text
    return started.json()


def test_block_download_of_a_hex_file_reads_back_the_new_identification(demo_api: TestClient) -> None:
    image = os.urandom(30_000)
    checked = _check(demo_api, SERVO, "axis-2.0.hex", intel_hex(image))
    assert checked.status_code == 200, checked.text
    body = checked.json()
    assert body["ok"] and body["file"]["bytes"] == len(image) and body["file"]["kind"] == "hex"
    assert body["file"]["start_address"] == "0x00008000"
    job = _download(demo_api, SERVO, body["file_id"])
    messages = []
    with demo_api.websocket_connect(job["links"]["progress"]) as socket:
        while True:
            message = socket.receive_json()
            messages.append(message)
            if message["state"] != "running":
                break
    assert messages[-1]["state"] == "done", (messages[-1].get("error"), messages[-1].get("result"))
    progress = messages[-1]["progress"]
    assert progress["done"] == progress["total"] == len(image) and progress["rate_per_s"] > 0
    result = _finished(demo_api, SERVO, job["id"])["result"]
    assert result["transfer"] == "block"
    assert result["software_id"] == f"0x{zlib.crc32(image):08X}"
    assert result["verified"] is True
    assert _sim(demo_api, SERVO).program.image == image
    info = demo_api.get(NODE.format(node=SERVO)).json()
    assert info["state"] == 1 and info["flash_ok"] and not info["bootloader"]


def test_a_drive_without_block_transfer_gets_the_image_segmented(demo_api: TestClient) -> None:
    image = os.urandom(2_000)
    file_id = _check(demo_api, FAN, "fan.bin", image).json()["file_id"]
    done = _finished(demo_api, FAN, _download(demo_api, FAN, file_id)["id"])
    assert done["state"] == "done", done
    assert done["result"]["transfer"] == "segmented"
    assert _sim(demo_api, FAN).program.image == image


def test_start_without_confirmation_is_428_naming_the_node(demo_api: TestClient) -> None:
    file_id = _check(demo_api, SERVO, "axis.bin", b"\x01" * 100).json()["file_id"]
    refused = demo_api.post(NODE.format(node=SERVO) + "/download", json={"file_id": file_id})
    assert refused.status_code == 428
    problem = refused.json()
    assert problem["confirm_node"] == SERVO
    assert problem["confirm_values"]["0x1F50 Program data"].startswith("axis.bin (100 bytes, CRC32 0x")
    control = demo_api.post(NODE.format(node=SERVO) + "/control/start", json={})
    assert control.status_code == 428 and control.json()["confirm_node"] == SERVO
    assert _sim(demo_api, SERVO).program.downloads == 0


def test_a_hex_file_with_a_bad_checksum_is_refused_with_its_line(demo_api: TestClient) -> None:
    refused = _check(demo_api, SERVO, "axis.hex", broken_checksum(intel_hex(os.urandom(200)), 3))
    assert refused.status_code == 422
    assert "line 3" in refused.json()["detail"] and "checksum" in refused.json()["detail"]


def test_a_file_for_another_product_is_refused(demo_api: TestClient) -> None:
    node = _sim(demo_api, SERVO)
    product = node.store.get(0x1018, 2)
    other = f'{{"product_code": "0x{(product + 1) & 0xFFFFFFFF:08X}"}}'
    refused = _check(demo_api, SERVO, "other.bin", b"\x00" * 64, identity=other).json()
    assert not refused["ok"] and refused["file_id"] is None
    assert f"0x{product:08X}" in refused["refused"]
    same = _check(demo_api, SERVO, "axis.bin", b"\x00" * 64, identity=f'{{"product_code": {product}}}').json()
    assert same["ok"] and same["file_id"] and not same["notes"]


def test_cancel_aborts_the_transfer_and_the_drive_keeps_its_program(demo_api: TestClient) -> None:
    before = _sim(demo_api, SERVO).program.image
    file_id = _check(demo_api, SERVO, "big.bin", os.urandom(1024 * 1024)).json()["file_id"]
    job = _download(demo_api, SERVO, file_id)
    url = NODE.format(node=SERVO) + f"/jobs/{job['id']}"
    assert wait_until(lambda: demo_api.get(url).json()["progress"]["done"] > 0, 30)
    assert demo_api.delete(f"/api/jobs/{job['id']}").status_code == 200
    done = _finished(demo_api, SERVO, job["id"])
    assert done["state"] == "cancelled"
    assert "0x08000000" in done["result"]["outcome"]
    assert _sim(demo_api, SERVO).program.image == before


def test_a_flash_error_is_reported_in_words(demo_api: TestClient) -> None:
    assert demo_api.put(FAULTS.format(node=SERVO), json={"flash_error": 5}).status_code == 200
    file_id = _check(demo_api, SERVO, "axis.bin", os.urandom(3000)).json()["file_id"]
    done = _finished(demo_api, SERVO, _download(demo_api, SERVO, file_id)["id"])
    assert done["state"] == "failed"
    assert "flash write error" in done["error"]


def test_power_loss_mid_flash_leaves_the_drive_in_its_bootloader_and_says_what_next(demo_api: TestClient) -> None:
    assert demo_api.put(FAULTS.format(node=SERVO), json={"power_loss_mid_flash": True}).status_code == 200
    image = os.urandom(5000)
    file_id = _check(demo_api, SERVO, "axis.bin", image).json()["file_id"]
    done = _finished(demo_api, SERVO, _download(demo_api, SERVO, file_id)["id"])
    assert done["state"] == "failed"
    assert "bootloader" in done["error"] and "download the program again" in done["error"]
    info = demo_api.get(NODE.format(node=SERVO)).json()
    assert info["bootloader"] and info["flash_text"] == "no valid program"
    # the tool's next step works: downloaded again to the bootloader, started, the device is back
    again = _finished(demo_api, SERVO, _download(demo_api, SERVO, file_id)["id"])
    assert again["state"] == "done", again
    assert again["result"]["software_id"] == f"0x{zlib.crc32(image):08X}"
    assert not demo_api.get(NODE.format(node=SERVO)).json()["bootloader"]


def test_the_download_is_in_the_audit_log(demo_api: TestClient) -> None:
    file_id = _check(demo_api, FAN, "fan-audit.bin", b"\x07" * 300).json()["file_id"]
    job = _finished(demo_api, FAN, _download(demo_api, FAN, file_id)["id"])
    assert job["state"] == "done", _why(job)
    rows = demo_api.get("/api/audit", params={"node_id": FAN}).json()
    program = [row for row in rows if row["origin"] == "program download"]
    assert len(program) == 3, program  # stop, the data, start
    assert any("fan-audit.bin (300 bytes" in (row["new_value"] or "") for row in program), program
    assert all(row["result"] not in ("sending", "failed") for row in program), program


@pytest.mark.slow  # a server process
def test_a_file_checked_by_one_server_is_downloaded_by_the_next_on_the_same_database(app_db_url: str) -> None:
    """Checked files live in the database (design: nothing that must survive a restart or be seen by a second
    server lives in one process's memory): a file checked by this process's app is downloaded by a `serve` process
    started afterwards on the same database, to the node it was checked for only."""
    image = os.urandom(2_000)
    with TestClient(create_app(plant_file=DEMO_PLANT, plant_bus=f"virtual:{fresh_channel()}@500000",
                               latency="0ms")) as first:
        file_id = _check(first, FAN, "fan-3.1.bin", image).json()["file_id"]
    port = free_port()
    server = CliProcess("serve", "--port", str(port), "--demo", env={"DRIVEBENCH_DATABASE_URL": app_db_url})
    try:
        with httpx.Client(base_url=f"http://127.0.0.1:{port}", timeout=30) as second:
            poll(lambda: second.get("/api/health").status_code == 200, START_TIMEOUT_S, "health")
            other = confirmed(second, "POST", NODE.format(node=SERVO) + "/download", json={"file_id": file_id})
            assert other.status_code == 404 and "No checked firmware file" in other.json()["detail"], other.text
            done = _finished(second, FAN, _download(second, FAN, file_id)["id"])
            assert done["state"] == "done", done
            assert done["result"]["software_id"] == f"0x{zlib.crc32(image):08X}", done["result"]
    finally:
        server.stop()


def test_only_the_newest_checked_files_of_a_node_are_kept(demo_api: TestClient) -> None:
    ids = [_check(demo_api, FAN, f"fan-{n}.bin", bytes([n]) * 64).json()["file_id"] for n in range(uploads.KEEP + 2)]
    servo_id = _check(demo_api, SERVO, "axis.bin", b"\x01" * 64).json()["file_id"]
    gone = confirmed(demo_api, "POST", NODE.format(node=FAN) + "/download", json={"file_id": ids[0]})
    assert gone.status_code == 404, gone.text
    assert _finished(demo_api, FAN, _download(demo_api, FAN, ids[-1])["id"])["state"] == "done"
    assert _finished(demo_api, SERVO, _download(demo_api, SERVO, servo_id)["id"])["state"] == "done"
