"""DriveBench under a sub-path (``serve --root-path /drivebench``, issue 33): uvicorn serves the app with the prefix
a reverse proxy strips, and every URL a page, a redirect or a cookie names carries it."""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest
import websockets.sync.client

from drivebench.web.app import create_app
from tests.conftest import DEMO_PLANT, _free_port, fresh_channel, serve_app, wait_until
from tests.transport.test_multiprocess import START_TIMEOUT_S, CliProcess

ROOT = "/drivebench"
NODE = "/sessions/demo-plant/nodes/3"
URL_ATTRIBUTE = re.compile(r'\b(href|src|action|hx-(?:get|post|put|patch|delete|push-url)|ws-connect'
                           r'|data-(?:api|ws|keepalive))="([^"]*)"')


@pytest.fixture(scope="module")
def server() -> Iterator[str]:
    """The demo plant served with uvicorn's root_path, as ``drivebench serve --root-path /drivebench`` does."""
    app = create_app(plant_file=DEMO_PLANT, plant_bus=f"virtual:{fresh_channel()}@500000", latency="0ms")
    with serve_app(app, root_path=ROOT) as url:
        yield url


def _urls(html: str) -> list[tuple[str, str]]:
    return [(name, value) for name, value in URL_ATTRIBUTE.findall(html) if value.startswith("/")]


@pytest.mark.parametrize("page", ["/", NODE, NODE + "?tab=control", "/monitor/demo-plant", "/tools",
                                  "/parameter-sets", "/profiles", "/remote"])
def test_every_url_on_a_page_carries_the_root_path(server: str, page: str) -> None:
    answer = httpx.get(server + page, headers={"Accept": "text/html"}, timeout=60)
    assert answer.status_code == 200, answer.text[:500]
    urls = _urls(answer.text)
    assert urls, "the page names no URL"
    outside = [(name, value) for name, value in urls if not value.startswith(ROOT + "/")]
    assert outside == [], f"URLs outside {ROOT}/ on {page}: {outside[:10]}"
    assert f'data-root="{ROOT}"' in answer.text


def test_fragments_carry_the_root_path(server: str) -> None:
    for fragment in (f"/ui{NODE}/parameters", f"/ui{NODE}/control", f"/ui{NODE}/tabs/pdo"):
        answer = httpx.get(server + fragment, headers={"HX-Request": "true", "X-DriveBench": "1"}, timeout=60)
        assert answer.status_code == 200, (fragment, answer.text[:500])
        outside = [(name, value) for name, value in _urls(answer.text) if not value.startswith(ROOT + "/")]
        assert outside == [], f"URLs outside {ROOT}/ in {fragment}: {outside[:10]}"


def test_redirects_and_cookies_stay_under_the_root_path(server: str) -> None:
    monitor = httpx.get(server + "/monitor", timeout=60)
    assert monitor.status_code == 307
    assert monitor.headers["location"] == f"{ROOT}/monitor/demo-plant"
    switched = httpx.get(server + "/language/de", params={"next": NODE}, timeout=60)
    assert switched.status_code == 303
    assert switched.headers["location"] == ROOT + NODE
    assert f"Path={ROOT}" in switched.headers["set-cookie"]


def test_api_and_static_answer_under_the_root_path(server: str) -> None:
    """The router, the access gate and the static files see the path without the prefix."""
    assert httpx.get(server + "/api/health", timeout=60).json()["status"] == "ok"
    assert httpx.get(server + "/static/app.js", timeout=60).status_code == 200
    assert httpx.get(server + "/api/sessions/demo-plant/nodes/3", timeout=60).status_code == 200


def test_the_live_node_table_carries_the_root_path(server: str) -> None:
    """The Plant page's node table comes again over its websocket: its links keep the prefix."""
    with websockets.sync.client.connect(server.replace("http://", "ws://") + "/ws/sessions/demo-plant/nodes",
                                        open_timeout=60) as socket:
        html = str(socket.recv(timeout=60))
    urls = _urls(html)
    assert urls, "the node table names no URL"
    outside = [(name, value) for name, value in urls if not value.startswith(ROOT + "/")]
    assert outside == [], f"URLs outside {ROOT}/ in the live node table: {outside[:10]}"


def test_a_job_names_its_urls_under_the_root_path(server: str) -> None:
    """An answer's links (a read job's self and progress) are addresses the client can open through the proxy."""
    job = _started(server + "/api/sessions/demo-plant/nodes/3/read-all")
    assert job["links"] == {"self": f"{ROOT}/api/jobs/{job['id']}", "progress": f"{ROOT}/ws/jobs/{job['id']}"}
    assert httpx.get(server + job["links"]["self"][len(ROOT):], timeout=60).json()["id"] == job["id"]


def _started(url: str) -> dict[str, object]:
    answer = httpx.post(url, headers={"X-DriveBench": "1"}, timeout=60)
    assert answer.status_code == 202, answer.text[:500]
    return dict(answer.json())


def test_serve_with_root_path_serves_pages_under_it(tmp_path: Path) -> None:
    """``drivebench serve --root-path /drivebench`` hands the prefix to uvicorn: its pages link under it."""
    port = _free_port()
    server = CliProcess("serve", "--demo", "--port", str(port), "--root-path", "/drivebench/",
                        env={"DRIVEBENCH_DATABASE_URL": f"sqlite:///{tmp_path / 'db.sqlite'}"})
    try:
        server.wait_for_line("DriveBench on")
        assert wait_until(lambda: _health(port), START_TIMEOUT_S)
        page = httpx.get(f"http://127.0.0.1:{port}/", headers={"Accept": "text/html"}, timeout=60)
        assert page.status_code == 200
        assert f'href="{ROOT}/static/app.css"' in page.text
    finally:
        server.stop()


def _health(port: int) -> bool:
    try:
        return httpx.get(f"http://127.0.0.1:{port}/api/health", timeout=5).status_code == 200
    except httpx.HTTPError:
        return False


def test_serve_refuses_a_root_path_that_is_no_sub_path(tmp_path: Path) -> None:
    server = CliProcess("serve", "--port", "0", "--root-path", "drivebench",
                        env={"DRIVEBENCH_DATABASE_URL": f"sqlite:///{tmp_path / 'db.sqlite'}"})
    server.wait_for_line("is not a sub-path")
    assert server.process.wait(timeout=START_TIMEOUT_S) == 1
