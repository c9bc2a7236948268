"""The ``ethercat`` section of a profile through the profiles API: its JSON schema names the EtherCAT states, the
shipped 8400 motec EtherCAT profile lists no Bootstrap, and an upload that leaves out a state every slave has is
refused in words."""

from __future__ import annotations

import json
from pathlib import Path

from fastapi.testclient import TestClient

from drivebench.config import REPO_ROOT
from tests.web.test_profiles_api import schema_errors, upload

ETHERCAT = REPO_ROOT / "device_profiles" / "lenze-8400-motec-ethercat.json"


def _copy(esm_states: list[str]) -> dict[str, object]:
    profile = json.loads(ETHERCAT.read_text())
    profile.update(id="ethercat-with-states", ethercat={"esm_states": esm_states})
    return profile


def test_the_schema_names_the_esm_states_and_the_shipped_unit_has_no_bootstrap(api: TestClient) -> None:
    schema = api.get("/api/profiles/schema").json()
    assert "ethercat" in schema["properties"]
    states = schema["$defs"]["EthercatSection"]["properties"]["esm_states"]
    assert set(states["items"]["enum"]) == {"Init", "Pre-Operational", "Bootstrap", "Safe-Operational", "Operational"}
    shipped = json.loads(ETHERCAT.read_text())
    assert schema_errors(shipped, schema, schema) == []
    assert "Bootstrap" not in shipped["ethercat"]["esm_states"]
    served = api.get("/api/profiles/lenze-8400-motec-ethercat").json()["ethercat"]
    assert served["esm_states"] == ["Init", "Pre-Operational", "Safe-Operational", "Operational"]
    assert schema_errors(_copy(["Init", "Pre-Operational", "Reboot"]), schema, schema) != []


def test_an_upload_without_a_mandatory_state_is_refused_and_one_with_bootstrap_is_taken(
        api: TestClient, user_dir: Path) -> None:
    refused = upload(api, "states.json", json.dumps(_copy(["Init", "Bootstrap", "Operational"])).encode())
    assert refused.status_code == 422 and refused.headers["content-type"] == "application/problem+json"
    assert "every EtherCAT slave has Pre-Operational, Safe-Operational (ETG.1000.6)" in refused.json()["detail"]
    twice = upload(api, "states.json", json.dumps(_copy(["Init", "Pre-Operational", "Safe-Operational",
                                                         "Operational", "Init"])).encode())
    assert twice.status_code == 422 and "listed twice" in twice.json()["detail"]
    assert not user_dir.exists() or list(user_dir.iterdir()) == []

    states = ["Init", "Pre-Operational", "Bootstrap", "Safe-Operational", "Operational"]
    taken = upload(api, "states.json", json.dumps(_copy(states)).encode())
    assert taken.status_code == 201, taken.text
    assert api.get("/api/profiles/ethercat-with-states").json()["ethercat"]["esm_states"] == states
