"""Opening a direct EtherCAT master (``ethercat:NIC``) through the real HTTP API and the Plant page's session form:
each reason it cannot run is said in words. No EtherCAT card and no slave here: the real pysoem opens ``lo``, where
nobody answers; the missing privilege is a real server process without CAP_NET_RAW; a missing pysoem is an import
made to fail (``sys.modules['pysoem'] = None``)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest
from fastapi.testclient import TestClient

from drivebench.transport.ethercat_soem import may_use_raw_sockets, network_cards
from drivebench.web.app import create_app
from tests.test_cli import free_port, poll
from tests.transport.test_ethercat_soem import NO_NET_RAW, PRIVILEGED
from tests.transport.test_multiprocess import START_TIMEOUT_S
from tests.web.test_sessions_api import assert_problem

pytestmark = pytest.mark.slow  # fault scenarios, timeouts or server processes: `make test-quick` leaves them out

HTMX = {"HX-Request": "true"}


@pytest.fixture
def api(app_db_url: str) -> Iterator[TestClient]:
    with TestClient(create_app()) as client:
        yield client


def test_without_the_extra_the_api_and_the_session_form_name_it(api: TestClient,
                                                                monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "pysoem", None)  # as if not installed: importing it fails
    body = assert_problem(api.post("/api/sessions", json={"bus": "ethercat:lo"}), 503)
    assert "needs pysoem: install DriveBench with its extra (pip install 'drivebench[ethercat]')" in str(body["detail"])
    form = api.post("/ui/sessions", data={"interface": "ethercat", "channel": "lo", "name": "Direct"}, headers=HTMX)
    assert form.status_code == 503 and "pip install &#39;drivebench[ethercat]&#39;" in form.text
    assert api.get("/api/sessions").json() == []
    assert ">ethercat (direct master: needs pip install &#39;drivebench[ethercat]&#39;)</option>" in api.get("/").text


@PRIVILEGED
def test_an_unknown_card_is_named_with_the_cards_present(api: TestClient) -> None:
    body = assert_problem(api.post("/api/sessions", json={"bus": "ethercat:eth9"}), 503)
    assert body["detail"] == f"This computer has no network card 'eth9'; it has {', '.join(network_cards())} " \
                             "(see ip link)."
    form = api.post("/ui/sessions", data={"interface": "ethercat", "channel": "eth9"}, headers=HTMX)
    assert form.status_code == 503 and "no network card &#39;eth9&#39;; it has" in form.text
    assert '<option value="ethercat" >ethercat</option>' in api.get("/").text  # installed and privileged: no note


@PRIVILEGED
def test_a_card_without_slaves_opens_and_says_no_slave_answered(api: TestClient) -> None:
    created = api.post("/api/sessions", json={"bus": "ethercat:lo", "name": "Direct on lo"})
    assert created.status_code == 201, created.text
    session = created.json()
    assert (session["interface"], session["bus"], session["node_count"]) == ("ethercat", "ethercat:lo", 0)
    assert session["state_text"] == ("Slave list not read: No EtherCAT slave answered on lo: check the cable from "
                                     "this card to the first slave's IN port, the slaves' power, and that no other "
                                     "master uses the card.")
    rescan = assert_problem(api.post(f"/api/sessions/{session['id']}/scan"), 502)
    assert str(rescan["detail"]).startswith("No EtherCAT slave answered on lo")
    assert api.delete(f"/api/sessions/{session['id']}").status_code == 204


@pytest.mark.skipif(os.geteuid() != 0 or shutil.which("setpriv") is None,
                    reason="dropping CAP_NET_RAW from a server process needs root and setpriv")
def test_a_server_without_cap_net_raw_says_how_to_grant_it(tmp_path: Path) -> None:
    assert may_use_raw_sockets()  # this test process has it; the server will not
    port = free_port()
    env = {**os.environ, "PYTHONUNBUFFERED": "1", "DRIVEBENCH_DATABASE_URL": f"sqlite:///{tmp_path / 'serve.db'}"}
    server = subprocess.Popen([*NO_NET_RAW, sys.executable, "-m", "drivebench.cli", "serve", "--port", str(port)],
                              env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        with httpx.Client(base_url=f"http://127.0.0.1:{port}", timeout=10) as client:
            poll(lambda: client.get("/api/health").json(), START_TIMEOUT_S, "health")
            refused = client.post("/api/sessions", json={"bus": "ethercat:lo"})
            assert refused.status_code == 503, refused.text
            assert refused.json()["detail"] == (
                "The direct EtherCAT master sends raw Ethernet frames on lo: run DriveBench as root or give its "
                "Python CAP_NET_RAW (setcap cap_net_raw+ep), or reach the slaves through a master's mailbox gateway "
                "(ethercat-mbg:HOST).")
            assert ">ethercat (direct master: needs root or CAP_NET_RAW)</option>" in client.get("/").text
    finally:
        server.terminate()
        server.wait(timeout=15)
