"""Issue 28 item 7 on the demo plant (real python-can virtual bus, simulated drives, HTTP API): a PDO on a COB-ID of
its own is its node's, whichever way the bus showed its communication parameter; a scan's requests are one COB-ID row.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from typing import Any

import can
import pytest
from fastapi.testclient import TestClient

from drivebench.web.app import create_app
from tests.confirming import confirmed
from tests.conftest import DEMO_PLANT, wait_for_value

DEMO = "/api/sessions/demo-plant"


@pytest.fixture
def foreign(channel: str) -> Iterator[can.BusABC]:
    """Another device on the demo plant's bus (the ``client`` fixture's channel)."""
    bus = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
    yield bus
    bus.shutdown()


def _cob_rows(client: TestClient) -> dict[int, dict[str, Any]]:
    return {row["cob_id"]: row for row in client.get(f"{DEMO}/monitor").json()["cob_ids"]}


def _counted(client: TestClient, cob_id: int, minimum: int = 1) -> dict[str, Any]:
    return wait_for_value(lambda: (row := _cob_rows(client).get(cob_id)) and row["total"] >= minimum and row, 30,
                          f"telegrams on 0x{cob_id:03X} counted")


def _send(bus: can.BusABC, cob_id: int, count: int = 3) -> None:
    for _ in range(count):
        bus.send(can.Message(arbitration_id=cob_id, data=b"\x01\x02", is_extended_id=False))


def test_a_moved_tpdo_is_its_nodes_and_its_default_no_longer(client: TestClient, foreign: can.BusABC) -> None:
    """Node 7's TPDO1 moved to 0x2A7 through the PDO editor's API: 0x2A7 is node 7's TPDO1 (not node 39's TPDO2, a
    node the session does not have), 0x187 is nobody's; made invalid (bit 31, a parameter write), 0x2A7 is no
    longer node 7's; a monitor reset keeps what the bus showed, node 7's boot-up forgets it."""
    pdo = client.get(f"{DEMO}/nodes/7/pdos/tpdo/1").json()
    assert pdo["cob_id"] == 0x187
    entries = [[entry["index"], entry["subindex"]] for entry in pdo["entries"]]
    applied = confirmed(client, "PUT", f"{DEMO}/nodes/7/pdos/tpdo/1", json={"cob_id": 0x2A7, "entries": entries})
    assert applied.status_code == 200 and applied.json()["ok"], applied.text
    assert client.post(f"{DEMO}/monitor/reset").status_code == 200  # what the bus showed outlives a reset
    _send(foreign, 0x187)
    _send(foreign, 0x2A7)
    moved = _counted(client, 0x2A7)
    assert (moved["service"], moved["node"]) == ("TPDO1", 7), moved
    default = _counted(client, 0x187)
    assert (default["service"], default["node"]) == ("Unknown", None), default
    nodes = [row["node"] for row in client.get(f"{DEMO}/monitor").json()["nodes"]]
    assert 39 not in nodes, nodes
    trace = client.get(f"{DEMO}/monitor/trace", params={"limit": 10000}).json()["rows"]
    assert {(row["service"], row["node"]) for row in trace if row["cob_id"] == "0x2A7"} == {("TPDO1", 7)}

    written = confirmed(client, "PUT", f"{DEMO}/nodes/7/parameters/0x1800.1", json={"raw": 0x800002A7, "check": False})
    assert written.status_code == 200, written.text
    client.post(f"{DEMO}/monitor/reset")
    _send(foreign, 0x2A7)
    assert _counted(client, 0x2A7)["node"] != 7, "an invalid PDO is not attributed"

    confirmed(client, "PUT", f"{DEMO}/nodes/7/parameters/0x1800.1", json={"raw": 0x2A7, "check": False})
    foreign.send(can.Message(arbitration_id=0x707, data=b"\x00", is_extended_id=False))  # node 7 booted
    client.post(f"{DEMO}/monitor/reset")
    _send(foreign, 0x187)
    assert _counted(client, 0x187)["node"] == 7, "after its boot-up, node 7's PDOs are on their defaults again"


def test_a_cob_id_read_or_written_as_a_parameter_is_attributed(client: TestClient, foreign: can.BusABC) -> None:
    """Node 3's TPDO5 (0x1804.1, default 0x283 in its profile) written as a parameter, node 12's RPDO1 (0x1400.1)
    moved by writes and then read: each COB-ID is its node's PDO, the defaults 0x283 and 0x20C no longer theirs. A
    write the device refused (abort) changes nothing: 0x24C stays what the predefined set says, 0x30C node 12's."""
    for node, ref, raw in ((3, "0x1804.1", 0x800002B3), (3, "0x1804.1", 0x2B3), (12, "0x1400.1", 0x8000020C),
                           (12, "0x1400.1", 0x23C)):
        written = confirmed(client, "PUT", f"{DEMO}/nodes/{node}/parameters/{ref}", json={"raw": raw, "check": False})
        assert written.status_code == 200, written.text
    faults = f"{DEMO}/simulator/nodes/12/faults"
    assert client.put(faults, json={"abort_code": 0x08000020}).status_code == 200
    refused = confirmed(client, "PUT", f"{DEMO}/nodes/12/parameters/0x1401.1", json={"raw": 0x24C, "check": False})
    assert refused.status_code >= 400, refused.text
    assert client.put(faults, json={}).status_code == 200
    client.post(f"{DEMO}/monitor/reset")
    read = client.get(f"{DEMO}/nodes/12/parameters/0x1400.1")
    assert read.status_code == 200 and read.json()["raw"] == 0x23C, read.text
    cob_ids = (0x2B3, 0x283, 0x23C, 0x20C, 0x24C, 0x30C)
    for cob_id in cob_ids:
        _send(foreign, cob_id)
    attributed = {cob_id: (row["service"], row["node"]) for cob_id in cob_ids for row in [_counted(client, cob_id)]}
    assert attributed == {0x2B3: ("TPDO5+", 3), 0x283: ("Unknown", None), 0x23C: ("RPDO1", 12),
                          0x20C: ("Unknown", None), 0x24C: ("RPDO1", 76), 0x30C: ("RPDO2", 12)}, attributed


def test_a_cob_id_only_read_by_the_pdo_editor_is_attributed(client: TestClient, foreign: can.BusABC) -> None:
    """Node 5's TPDO2 is on 0x2C5 in the device (its keypad, a stored configuration: nothing on the bus said so);
    once the PDO editor has read the node's PDOs, 0x2C5 is node 5's TPDO2 and 0x285 no longer node 5's."""
    drive = client.app.state.drivebench.plants["demo-plant"].nodes[5]  # type: ignore[attr-defined]
    drive.store.set(0x1801, 1, 0x2C5)
    listed = client.get(f"{DEMO}/nodes/5/pdos")
    assert listed.status_code == 200 and 0x2C5 in [pdo["cob_id"] for pdo in listed.json()], listed.text
    for cob_id in (0x2C5, 0x285):
        _send(foreign, cob_id)
    attributed = {cob_id: (row["service"], row["node"]) for cob_id in (0x2C5, 0x285)
                  for row in [_counted(client, cob_id)]}
    assert attributed == {0x2C5: ("TPDO2", 5), 0x285: ("Unknown", None)}, attributed


def test_a_scan_is_one_cob_id_row(client: TestClient) -> None:
    """After a scan, the requests to the 121 node ids that never answered are one COB-ID row, 0x601-0x67F; the
    requests to nodes 3, 5, 7 and 12 keep their own rows, as do 0x645 and 0x64C (the SDO2 requests of nodes 5 and
    12: their profiles' ``sdo_channels``)."""
    assert client.post(f"{DEMO}/scan", json={"timeout_s": 0.3}).status_code == 200
    rows = client.get(f"{DEMO}/monitor").json()["cob_ids"]
    requests = [row for row in rows if 0x600 < row["cob_id"] < 0x680]
    scan = [row for row in requests if row["node"] is None]
    assert len(scan) == 1, [row["text"] for row in scan]
    assert scan[0]["ids"] == 121 and scan[0]["text"] == "0x601–0x67F" and scan[0]["total"] >= 121, scan[0]
    assert sorted(row["node"] for row in requests if row["node"] is not None) == [3, 5, 5, 7, 12, 12]
    shown = client.put(f"{DEMO}/monitor/filter", json={"cob_min": 0x650, "cob_max": 0x660})
    assert shown.status_code == 200
    assert [row["ids"] for row in client.get(f"{DEMO}/monitor").json()["cob_ids"]] == [121]


def test_a_set_download_that_moves_a_pdo_is_attributed(app_db_url: str, channel: str, foreign: can.BusABC) -> None:
    """A parameter set of node 7 whose 0x1801.1 (TPDO2) says 0x2B7, downloaded: 0x2B7 is node 7's TPDO2."""
    app = create_app(plant_file=DEMO_PLANT, plant_bus=f"virtual:{channel}@500000", latency="0ms")
    with TestClient(app) as demo_api:
        _download_a_moved_tpdo(demo_api, foreign)


def _download_a_moved_tpdo(demo_api: TestClient, foreign: can.BusABC) -> None:
    sets = "/api/parameter-sets"
    started = demo_api.post(f"{sets}/upload", json={"session_id": "demo-plant", "node_id": 7, "name": "Axis"})
    assert started.status_code == 202, started.text
    job = wait_for_value(lambda: (job := demo_api.get(f"{sets}/jobs/{started.json()['id']}").json())["state"]
                         != "running" and job, 60, "the set upload ends")
    exported = json.loads(demo_api.get(f"{sets}/{job['set_id']}/export").text)
    moved = [parameter for parameter in exported["parameters"] if parameter["ref"] == "0x1801.1"]
    assert moved and moved[0]["value"] == 0x287, moved
    moved[0]["value"] = 0x2B7
    exported["name"] = "Axis, TPDO2 on 0x2B7"
    imported = demo_api.post(f"{sets}/import", files={"file": ("axis.json", json.dumps(exported).encode())})
    assert imported.status_code == 201, imported.text
    download = confirmed(demo_api, "POST", f"{sets}/{imported.json()['set']['id']}/download",
                         json={"session_id": "demo-plant", "node_id": 7})
    assert download.status_code == 202, download.text
    done = wait_for_value(lambda: (job := demo_api.get(f"{sets}/jobs/{download.json()['id']}").json())["state"]
                          != "running" and job, 60, "the set download ends")
    assert {line["ref"]: line["status"] for line in done["report"]}["0x1801.1"] == "written", done
    _send(foreign, 0x2B7)
    assert (_counted(demo_api, 0x2B7)["service"], _counted(demo_api, 0x2B7)["node"]) == ("TPDO2", 7)
