"""Sub 0 of an array or record whose profile lists only its members is typed as CiA 301 and the exported EDS say:
"Highest sub-index supported", UNSIGNED8, read-only (issue 33: the 8400 units' code arrays came back untyped as
"(not in the profile)"). Read through the REST API from the demo plant's simulated units, CAN and EtherCAT."""

from __future__ import annotations

import pytest
from fastapi.testclient import TestClient

CAN_8400 = "/api/sessions/demo-plant/nodes/5"
ECAT_8400 = "/api/sessions/ethercat-line/nodes/1"


@pytest.mark.parametrize(("node", "index", "highest"), [
    (ECAT_8400, 0x5C93, 2), (ECAT_8400, 0x5FFD, 11), (ECAT_8400, 0x29C7, None), (ECAT_8400, 0x5A20, None),
    (CAN_8400, 0x5FFD, None), (CAN_8400, 0x5C93, None)])
def test_sub_zero_of_a_code_array_is_typed(demo_api: TestClient, node: str, index: int, highest: int | None) -> None:
    read = demo_api.get(f"{node}/parameters/0x{index:04X}.0")
    assert read.status_code == 200, read.text
    value = read.json()
    assert "(not in the profile)" not in value["name"] and "Highest sub-index supported" in value["name"]
    assert isinstance(value["raw"], int) and value["display"] == str(value["raw"])  # UNSIGNED8, not DOMAIN bytes
    if highest is not None:
        assert value["raw"] == highest
