"""A device the code has never heard of: a profile JSON with a ``switches`` section, written here and uploaded, shows
in the DIP-switch calculator, the COB-ID table and the network planner with no code change, and computes node id
and baud rate from its switch positions both ways. A bad switches section is refused with the reason and where."""

from __future__ import annotations

import copy
import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient

from drivebench.config import settings
from drivebench.web.app import create_app

KEY = "acme-widget"
PROFILE_ID = "acme-widget-drive"

# Six address switches A1 … A6 worth 1 … 32 (node ids 1 … 60 by switches, 61 … 63 only by P100) and two baud
# switches B1 B2: OFF OFF = baud rate from P101, ON OFF = 125, OFF ON = 250, ON ON = 500 kbit/s.
SWITCHES: dict[str, Any] = {
    "key": KEY,
    "aliases": ["widget"],
    "name": "ACME widget drive with switch block",
    "short_name": "ACME widget",
    "manual": "ACME widget manual, ch. 3",
    "switches": [{"label": f"A{n}", "role": "address", "weight": 2 ** (n - 1)} for n in range(6, 0, -1)]
    + [{"label": "B1", "role": "baud"}, {"label": "B2", "role": "baud"}],
    "baud_table": [
        {"baud_kbit": 50, "positions": {"B1": False, "B2": False}},
        {"baud_kbit": 125, "positions": {"B1": True, "B2": False}},
        {"baud_kbit": 250, "positions": {"B1": False, "B2": True}},
        {"baud_kbit": 500, "positions": {"B1": True, "B2": True}},
    ],
    "baud_table_source": "ch. 3.2",
    "switch_node_range": [1, 60],
    "all_address_off": "node_from_parameter",
    "all_baud_off": "baud_from_parameter",
    "baud_rates_kbit": [50, 125, 250, 500],
    "node_parameter": {"code": "P100", "range": [1, 63], "default": 9,
                       "invalid": "{code} = {value} is outside {lo} … {hi}."},
    "baud_parameter": {"code": "P101", "rates_kbit": [50, 125, 250, 500], "default_kbit": 50,
                       "invalid": "{code} cannot select {value} kbit/s."},
    "settings": [
        {"code": "P100", "sets": "node_id", "meaning": "node id {node_id}", "note": "A1 … A6 OFF."},
        {"code": "P101", "sets": "baud", "values": {"50": 0, "125": 1, "250": 2, "500": 3},
         "meaning": "{baud_kbit} kbit/s", "note": "B1, B2 OFF."},
    ],
    "rules": [{"text": "3.1: node id = sum of the ON address switches.", "when": ["node_from_switches"]},
              {"text": "3.1: all address switches OFF: node id from P100.", "when": ["node_from_parameter"]}],
    "cob_ids": {"services": [
        {"name": "NMT", "channel": "nmt", "base": "0x000", "direction": "to node", "node_specific": False},
        {"name": "TPDO1", "channel": "pdo1", "base": "0x180", "direction": "from node"},
        {"name": "RPDO1", "channel": "pdo1", "base": "0x200", "direction": "to node"},
        {"name": "SDO1 tx", "channel": "sdo1", "base": "0x580", "direction": "from node"},
        {"name": "SDO1 rx", "channel": "sdo1", "base": "0x600", "direction": "to node"},
        {"name": "Heartbeat", "channel": "heartbeat", "base": "0x700", "direction": "from node"},
    ]},
}
PROFILE: dict[str, Any] = {
    "id": PROFILE_ID,
    "family": "acme",
    "identity": {"vendor_name": "ACME", "vendor_id": "0x00ACE", "product_name": "Widget drive"},
    "switches": SWITCHES,
}


def upload(api: TestClient, profile: dict[str, Any], name: str = "widget.json") -> Any:
    return api.post("/api/profiles", files={"file": (name, json.dumps(profile).encode())})


@pytest.fixture
def widget_api(user_dir: Path, app_db_url: str, monkeypatch: pytest.MonkeyPatch) -> Iterator[TestClient]:
    """The app (its own database, uploads into ``user_dir``) with the widget profile uploaded."""
    monkeypatch.setattr(settings, "user_profiles_dir", user_dir)
    with TestClient(create_app()) as api:
        response = upload(api, PROFILE)
        assert response.status_code == 201, response.text
        yield api


def test_uploaded_switches_section_is_listed_and_decodes_and_encodes(widget_api: TestClient) -> None:
    api = widget_api
    assert KEY in [f["key"] for f in api.get("/api/tools/dip").json()]

    decoded = api.get(f"/api/tools/dip/{KEY}", params={"on": "A1,A3,A5,B2"}).json()["result"]  # 1 + 4 + 16
    assert (decoded["node_id"], decoded["node_id_source"], decoded["baud_kbit"], decoded["baud_source"]) == (
        21, "switches", 250, "switches")
    assert decoded["rules_applied"] == ["3.1: node id = sum of the ON address switches."]
    assert {a["code"]: a["value"] for a in decoded["alternative"]} == {"P100": 21, "P101": 2}

    encoded = api.get(f"/api/tools/dip/{PROFILE_ID}", params={"node_id": 21, "baud_kbit": 250}).json()
    assert {label for label, on in encoded["result"]["switches"].items() if on} == {"A1", "A3", "A5", "B2"}
    cob = {c["service"]: c["cob_id"] for c in encoded["cob_ids"]}
    assert (cob["TPDO1"], cob["SDO1 rx"], cob["NMT"]) == (0x180 + 21, 0x600 + 21, 0)

    factory = api.post("/api/tools/dip/widget", json={"switches": {}}).json()["result"]  # all OFF: P100 / P101
    assert (factory["node_id"], factory["node_id_source"], factory["baud_kbit"], factory["baud_source"]) == (
        9, "P100", 50, "P101")
    only_by_parameter = api.get(f"/api/tools/dip/{KEY}", params={"node_id": 62, "baud_kbit": 125})
    assert only_by_parameter.status_code == 422
    assert only_by_parameter.json()["alternative"][0] == {"code": "P100", "value": 62, "meaning": "node id 62",
                                                          "note": "A1 … A6 OFF."}


def test_uploaded_device_in_the_page_and_the_planner(widget_api: TestClient) -> None:
    api = widget_api
    page = api.get("/tools")
    assert f'data-family="{KEY}"' in page.text and ">ACME widget</button>" in page.text
    block = api.post("/ui/tools/dip", data={"family": KEY, "on": ["A2"], "toggle": "B1"})
    assert block.status_code == 200
    assert block.text.count('class="dip-switch') == 8
    assert 'id="dip-node-value">2<' in block.text and 'id="dip-baud-value">125 kbit/s<' in block.text
    report = api.post("/api/tools/planner/check", json={"nodes": [
        {"device": KEY, "node_id": 3, "baud_kbit": 500},
        {"device": "lenze-8400-motec", "node_id": 3, "baud_kbit": 500}]}).json()
    assert [f["kind"] for f in report["findings"]] == ["duplicate_node_id"]
    assert {row["hex"] for row in report["cob_table"]} >= {"0x183", "0x603"}


@pytest.mark.parametrize(("change", "words"), [
    (lambda s: s["baud_table"][1]["positions"].update({"B3": True}),
     "switches: baud_table row 1 (125 kbit/s) names switches B1, B2, B3; it must name each baud switch (B1, B2)"),
    (lambda s: s["switches"][0].update({"weight": 3}), "switches: address switch weights must be distinct powers"),
    (lambda s: s.update({"switch_node_range": [1, 99]}), "switches: switch_node_range [1, 99] is not within 1 … 63"),
    (lambda s: s["cob_ids"]["services"][1].update({"shares_with": "SDO9"}),
     "shares_with names 'SDO9', which is not a service"),
    (lambda s: s["node_parameter"].update({"invalid": "{code} is {nonsense}"}), "may use {code}, {hi}, {lo}, {value}"),
])
def test_a_bad_switches_section_is_refused_with_the_reason(api: TestClient, user_dir: Path, change: Any,
                                                           words: str) -> None:
    profile = copy.deepcopy(PROFILE)
    change(profile["switches"])
    response = upload(api, profile)
    assert response.status_code == 422
    assert response.headers["content-type"].startswith("application/problem+json")
    assert words in response.json()["detail"]
    assert PROFILE_ID not in [p["id"] for p in api.get("/api/profiles").json()]
    assert not user_dir.exists() or not list(user_dir.iterdir())
    assert KEY not in [f["key"] for f in api.get("/api/tools/dip").json()]


def test_a_switch_block_under_a_shipped_key_is_refused(api: TestClient) -> None:
    profile = copy.deepcopy(PROFILE)
    profile["switches"]["aliases"] = ["MOTEC"]  # an alias of the 8400 motec's block
    response = upload(api, profile)
    assert response.status_code == 422
    assert "belong to the switch block of profile 'lenze-8400-motec-canopen'" in response.json()["detail"]
    decoded = api.get("/api/tools/dip/motec", params={"on": "16,4,2,1,a"}).json()["result"]
    assert decoded["node_id"] == 23  # still the 8400 motec's
