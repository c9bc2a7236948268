"""DriveBench behind a real reverse proxy at a sub-path (issue 33): Debian's nginx serves /drivebench/ from a
DriveBench started with root_path /drivebench (``serve --root-path``), or from one started without it that believes
the proxy's ``X-Forwarded-Prefix`` (``serve --forwarded-allow-ips``); a browser works through it, websockets too,
and asks for nothing outside /drivebench/."""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import time
import urllib.request
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from drivebench.web.app import create_app
from drivebench.web.forwarded_prefix import proxied as believing_proxies
from tests.conftest import DEMO_PLANT, fresh_channel, screenshot, serve_app

expect = pytest.importorskip("playwright.sync_api").expect

ROOT = "/drivebench"
WAIT_MS = 30_000
NGINX_CONF = """
{user}
daemon off;
pid {dir}/nginx.pid;
error_log {dir}/error.log warn;
events {{ worker_connections 256; }}
http {{
  access_log off;
  client_body_temp_path {dir}/body;
  proxy_temp_path {dir}/proxy;
  fastcgi_temp_path {dir}/fastcgi;
  uwsgi_temp_path {dir}/uwsgi;
  scgi_temp_path {dir}/scgi;
  server {{
    listen 127.0.0.1:{port};
    location {root}/ {{
      proxy_pass {upstream}/;
      proxy_http_version 1.1;
      proxy_set_header Upgrade $http_upgrade;
      proxy_set_header Connection "upgrade";
      proxy_set_header Host $host:$server_port;
      proxy_read_timeout 300s;
      {extra}
    }}
  }}
}}
"""


def _nginx() -> str:
    found = shutil.which("nginx") or next((p for p in ("/usr/sbin/nginx",) if Path(p).exists()), None)
    if found is None:
        pytest.skip("no nginx binary: `make test` installs Debian's nginx (apt-get install nginx)")
    return found


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


@pytest.fixture(scope="module", params=["root-path", "forwarded-prefix"])
def proxied(tmp_path_factory: pytest.TempPathFactory, request: pytest.FixtureRequest) -> Iterator[str]:
    """nginx on a free loopback port proxying /drivebench/ to the demo plant served with root_path, or served
    without it and told the prefix by nginx's X-Forwarded-Prefix; its base URL."""
    nginx = _nginx()
    app = create_app(plant_file=DEMO_PLANT, plant_bus=f"virtual:{fresh_channel()}@500000", latency="0ms")
    by_header = request.param == "forwarded-prefix"
    served = serve_app(believing_proxies(app, "127.0.0.1"), proxy_headers=False) if by_header else \
        serve_app(app, root_path=ROOT)
    with served as upstream:
        folder = tmp_path_factory.mktemp("nginx")
        port = _free_port()
        config = folder / "nginx.conf"
        extra = f"proxy_set_header X-Forwarded-Prefix {ROOT};" if by_header else ""
        config.write_text(NGINX_CONF.format(user="user root;" if os.geteuid() == 0 else "", dir=folder, port=port,
                                            root=ROOT, upstream=upstream, extra=extra), encoding="utf-8")
        process = subprocess.Popen([nginx, "-p", str(folder), "-c", str(config)], stdout=subprocess.DEVNULL,
                                   stderr=subprocess.PIPE)
        base = f"http://127.0.0.1:{port}{ROOT}"
        try:
            _wait_for(base + "/api/health", process, folder)
            yield base
        finally:
            process.terminate()
            process.wait(timeout=30)


def _wait_for(url: str, process: subprocess.Popen[bytes], folder: Path) -> None:
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        if process.poll() is not None:
            log = folder / "error.log"
            pytest.fail(f"nginx stopped: {process.stderr.read() if process.stderr else b''!r} "
                        f"{log.read_text() if log.exists() else ''}")
        try:
            with urllib.request.urlopen(url, timeout=10) as answer:
                if answer.status == 200:
                    return
        except OSError:
            pass
        time.sleep(0.2)
    pytest.fail(f"nginx did not answer {url}")


def test_plant_and_parameters_through_nginx_at_a_sub_path(proxied: str, page: Any) -> None:
    requested: list[str] = []
    page.on("request", lambda request: requested.append(request.url))
    page.on("websocket", lambda socket: requested.append(socket.url))
    page.goto(proxied + "/")
    table = page.locator("#nodes-demo-plant")
    expect(table).to_be_visible(timeout=WAIT_MS)
    # Live: the websocket (through the proxy) replaces the node table about twice a second.
    table.evaluate("t => { t.dataset.before = 'yes'; }")
    expect(page.locator("#nodes-demo-plant:not([data-before])")).to_be_visible(timeout=WAIT_MS)

    page.locator(f"a[href='{ROOT}/sessions/demo-plant/nodes/3']").first.click()
    expect(page.locator("h1")).to_contain_text("Node 3", timeout=WAIT_MS)
    expect(page.locator("nav.tabs a.active")).to_have_text("Parameters")
    row = page.locator("tr[data-ref='P0918']")
    row.get_by_role("button", name="Read").click()
    expect(row.locator("td.val .v")).to_be_visible(timeout=WAIT_MS)
    screenshot(page, "root-path-parameters")

    origin = proxied[: -len(ROOT)]
    outside = [url for url in requested if not url.replace("ws://", "http://", 1).startswith(proxied + "/")]
    assert outside == [], f"requests outside {ROOT}/: {outside[:10]}"
    assert any(url.startswith(origin.replace("http://", "ws://") + ROOT + "/ws/") for url in requested)
