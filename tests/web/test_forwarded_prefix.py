"""``X-Forwarded-Prefix`` of a trusted reverse proxy (issue 33): a DriveBench served without a root path puts the
prefix a proxy names in front of every URL of the pages it answers through that proxy, through a real uvicorn;
from an address ``--forwarded-allow-ips`` does not name the header changes nothing, and a prefix that is no
sub-path is refused in words."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest
import websockets.sync.client

from drivebench.web.app import create_app
from drivebench.web.forwarded_prefix import proxied, sub_path
from tests.conftest import DEMO_PLANT, _free_port, fresh_channel, serve_app, wait_until
from tests.transport.test_multiprocess import START_TIMEOUT_S, CliProcess
from tests.web.test_root_path import _health, _urls

PREFIX = "/line-3/drivebench"
NODE = "/sessions/demo-plant/nodes/3"


def _served(trusted: str) -> Iterator[str]:
    app = create_app(plant_file=DEMO_PLANT, plant_bus=f"virtual:{fresh_channel()}@500000", latency="0ms")
    with serve_app(proxied(app, trusted), proxy_headers=False) as url:
        yield url


@pytest.fixture(scope="module")
def trusting() -> Iterator[str]:
    """The demo plant behind a proxy on 127.0.0.1 (``serve --forwarded-allow-ips 127.0.0.1``)."""
    yield from _served("127.0.0.1")


@pytest.fixture(scope="module")
def distrusting() -> Iterator[str]:
    """The demo plant trusting only a proxy on another machine: the test's own requests are a client's."""
    yield from _served("10.20.0.5")


def _page(url: str, **headers: str) -> httpx.Response:
    answer = httpx.get(url, headers={"Accept": "text/html", **headers}, timeout=60)
    assert answer.status_code == 200, answer.text[:500]
    return answer


@pytest.mark.parametrize("page", ["/", NODE, NODE + "?tab=control", "/tools"])
def test_every_url_carries_the_prefix_the_trusted_proxy_names(trusting: str, page: str) -> None:
    html = _page(trusting + page, **{"X-Forwarded-Prefix": PREFIX + "/"}).text
    outside = [(name, value) for name, value in _urls(html) if not value.startswith(PREFIX + "/")]
    assert _urls(html) and outside == [], f"URLs outside {PREFIX}/ on {page}: {outside[:10]}"
    assert f'data-root="{PREFIX}"' in html


def test_the_same_server_answers_at_the_top_without_the_header(trusting: str) -> None:
    html = _page(trusting + "/").text
    assert 'href="/static/app.css"' in html and 'data-root=""' in html


def test_redirects_cookies_and_websockets_follow_the_prefix(trusting: str) -> None:
    header = {"X-Forwarded-Prefix": PREFIX}
    switched = httpx.get(trusting + "/language/de", params={"next": NODE}, headers=header, timeout=60)
    assert switched.status_code == 303 and switched.headers["location"] == PREFIX + NODE
    assert f"Path={PREFIX}" in switched.headers["set-cookie"]
    assert httpx.get(trusting + "/api/health", headers=header, timeout=60).json()["status"] == "ok"
    with websockets.sync.client.connect(trusting.replace("http://", "ws://") + "/ws/sessions/demo-plant/nodes",
                                        additional_headers=header, open_timeout=60) as socket:
        html = str(socket.recv(timeout=60))
    outside = [(name, value) for name, value in _urls(html) if not value.startswith(PREFIX + "/")]
    assert _urls(html) and outside == [], outside[:10]


def test_the_header_of_a_client_is_not_believed(distrusting: str) -> None:
    html = _page(distrusting + "/", **{"X-Forwarded-Prefix": "/elsewhere"}).text
    assert 'href="/static/app.css"' in html and "/elsewhere" not in html


@pytest.mark.parametrize("value", ["drivebench", "/a/../b", "/a//b", "/a b", "https://evil.example/x"])
def test_a_prefix_that_is_no_sub_path_is_refused_in_words(trusting: str, value: str) -> None:
    answer = httpx.get(trusting + "/", headers={"X-Forwarded-Prefix": value}, timeout=60)
    assert answer.status_code == 400
    assert answer.headers["content-type"] == "application/problem+json"
    assert "no sub-path" in answer.json()["detail"] and repr(value) in answer.json()["detail"]


def test_sub_path_reads_the_header_as_a_path() -> None:
    assert sub_path("/drivebench/") == "/drivebench"
    assert sub_path("/") == ""
    assert sub_path("/a/./b") is None


def test_serve_believes_the_prefix_only_from_the_proxies_it_names(tmp_path: Path) -> None:
    """``drivebench serve --forwarded-allow-ips 127.0.0.1`` wraps the app: the header from 127.0.0.1 is believed."""
    port = _free_port()
    server = CliProcess("serve", "--demo", "--port", str(port), "--forwarded-allow-ips", "127.0.0.1",
                        env={"DRIVEBENCH_DATABASE_URL": f"sqlite:///{tmp_path / 'db.sqlite'}"})
    try:
        server.wait_for_line("DriveBench on")
        assert wait_until(lambda: _health(port), START_TIMEOUT_S)
        html = _page(f"http://127.0.0.1:{port}/", **{"X-Forwarded-Prefix": PREFIX}).text
        assert f'href="{PREFIX}/static/app.css"' in html
        forwarded = httpx.get(f"http://127.0.0.1:{port}/api/health", timeout=60,
                              headers={"X-Forwarded-For": "10.1.2.3", "X-Forwarded-Proto": "https"})
        assert forwarded.status_code == 200  # uvicorn's proxy handling still runs behind the prefix
    finally:
        server.stop()
