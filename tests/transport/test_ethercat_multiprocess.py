"""`drivebench simulate` serves EtherCAT slaves behind a simulated master's mailbox gateway (UDP on 127.0.0.1) in one
process; `drivebench serve --bus ethercat-mbg:127.0.0.1:PORT` reaches them from another: the slave list, C00039/1 of
the 8400 motec EtherCAT unit, a verified write, the state machine, and the manual's refusal of a PDO mapping write
outside Pre-Operational - all through the HTTP API of the server process."""

from __future__ import annotations

import json
import signal
from pathlib import Path

import httpx
import pytest

from tests.test_cli import free_port, poll, run_cli
from tests.transport.test_multiprocess import START_TIMEOUT_S, CliProcess

pytestmark = pytest.mark.slow  # fault scenarios, timeouts or server processes: `make test-quick` leaves them out

LINE = {"name": "Two-slave line", "ethercat": {"name": "EtherCAT line", "slaves": [
    {"station": 1001, "profile": "lenze-8400-motec-ethercat", "name": "Palletiser"},
    {"station": 1002, "profile": "lenze-8400-motec-ethercat", "name": "Turntable"}]}}


def start_line(tmp_path: Path) -> tuple[CliProcess, str]:
    plant = tmp_path / "line.json"
    plant.write_text(json.dumps(LINE), encoding="utf-8")
    simulator = CliProcess("simulate", "--plant", str(plant), "--ethercat-port", "0", "--latency", "0ms")
    spec = simulator.wait_for_line(r"behind (ethercat-mbg:127\.0\.0\.1:\d+)")[1]
    return simulator, spec


def test_serve_reaches_ethercat_slaves_simulated_by_another_process(tmp_path: Path) -> None:
    simulator, spec = start_line(tmp_path)
    port = free_port()
    server = CliProcess("serve", "--port", str(port), "--bus", spec,
                        env={"DRIVEBENCH_DATABASE_URL": f"sqlite:///{tmp_path / 'serve.db'}"})
    try:
        with httpx.Client(base_url=f"http://127.0.0.1:{port}", timeout=10) as api:
            poll(lambda: api.get("/api/health").json(), START_TIMEOUT_S, "health")
            (session,) = api.get("/api/sessions").json()
            assert (session["interface"], session["bus"]) == ("ethercat-mbg", spec)
            base = f"/api/sessions/{session['id']}/nodes"
            nodes = api.get(base).json()
            assert [(n["node_id"], n["station"], n["device"], n["nmt_state"]) for n in nodes] == [
                (1, 1001, "Palletiser", "Pre-Operational"), (2, 1002, "Turntable", "Pre-Operational")]

            value = api.get(f"{base}/1/parameters/C00039/1").json()
            assert (value["raw"], value["display"]) == (0x0FA0, "40.00 %")
            written = api.put(f"{base}/1/parameters/C00039/1", json={"value": "12.5"})
            assert written.status_code == 200, written.text
            assert written.json()["verified"] is True
            assert api.get(f"{base}/1/parameters/C00039/1").json()["raw"] == 1250

            stopped = api.post(f"{base}/1/nmt", json={"command": "stop"})  # EtherCAT: to Safe-Operational
            assert stopped.status_code == 200, stopped.text
            assert stopped.json()["nmt_state"] == "Safe-Operational"
            refused = api.put(f"{base}/1/parameters/0x1A00.1", json={"raw": 0x5C930110})
            assert refused.status_code >= 400
            problem = refused.json()
            assert problem["abort_code"] == "0x08000022"
            assert problem["abort_text"] == ("Due to the current device state, data cannot be transferred to the "
                                             "application or stored in the application")
            assert api.get(base).json()[0]["mailbox"]["aborts"] >= 1
    finally:
        codes = [server.stop(), simulator.stop()]
    assert codes in ([0, 0], [-signal.SIGTERM, 0]), "serve and simulate end on SIGTERM"


def test_serve_with_a_silent_mailbox_gateway_says_so(capsys: pytest.CaptureFixture[str]) -> None:
    port = free_port()  # nobody answers on it
    assert run_cli(["serve", "--port", "0", "--bus", f"ethercat-mbg:127.0.0.1:{port}"]) == 1
    err = capsys.readouterr().err
    assert f"ethercat-mbg:127.0.0.1:{port}" in err and "did not answer" in err and "mailbox gateway" in err
    assert "Traceback" not in err
