"""Shared fixtures: a simulated plant on a fresh virtual bus, the real app on it, a live server, a browser."""

from __future__ import annotations

import contextlib
import functools
import inspect
import itertools
import os
import re
import shutil
import socket
import threading
import time
import uuid
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TypeVar

import can
import pytest
import uvicorn
from argon2 import PasswordHasher, profiles
from fastapi.testclient import TestClient
from hypothesis import settings
from starlette.types import ASGIApp

from drivebench.config import REPO_ROOT
from drivebench.config import settings as app_settings
from drivebench.device.calculators.dip import SwitchDevices
from drivebench.device.profiles.loader import ProfileRegistry, load_profile_file
from drivebench.services.storage import database
from drivebench.services.users import accounts
from drivebench.simulator.plant import Plant, PlantFile
from drivebench.web.app import create_app
from tests.pg_cluster import PostgresCluster, shared_cluster

pytest_plugins = ["tests.thread_check"]

DEMO_PLANT = REPO_ROOT / "plants" / "demo.json"
ARTIFACTS = REPO_ROOT / "test-artifacts"
CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync", "--no-first-run", "--disable-quic"]
_channels = itertools.count(1)

# CI runs the same examples every time (a failure is reproducible); `HYPOTHESIS_PROFILE=dev` explores anew.
settings.register_profile("ci", derandomize=True, deadline=None, print_blob=True)
settings.register_profile("dev", deadline=None)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))

# Starlette's TestClient addresses every request to ``testserver``: the tests' server has that name, as a deployment
# names its own with `serve --allowed-host` (any other Host is refused: DNS rebinding).
app_settings.allowed_hosts = [*app_settings.allowed_hosts, "testserver"]


BROWSER_FIXTURES = {"browser", "page", "own_page"}
"""Fixtures that start Chromium: a test using one is a browser test (``-m "not browser"`` leaves it out)."""

SLOW_FIXTURES = BROWSER_FIXTURES | {"live_server", "demo_server", "postgres"}
"""Fixtures that start a browser, a uvicorn server or the PostgreSQL cluster: a test using one (directly or through
another fixture) is marked ``slow`` on collection, as is a test marked ``browser`` or ``postgresql`` (the PostgreSQL
variant of a ``database_url`` test; its SQLite twin stays in the quick subset) or whose function or fixtures start
a server or a process (:data:`STARTS_A_SERVER`). ``make test-quick`` (``-m "not slow"``) leaves them out; new tests
of these kinds are covered without a hand-written mark."""

SLOW_MARKS = ("browser", "postgresql")

STARTS_A_SERVER = re.compile(r"\bserve_app\(|\bdemo_server_with_own_db\(|\bPopen\(")
"""Calls that start a uvicorn server or a process: a test whose function or one of whose fixtures makes one is
marked ``slow`` on collection too."""


@functools.cache
def _starts_a_server(func: Callable[..., object]) -> bool:
    try:
        return bool(STARTS_A_SERVER.search(inspect.getsource(func)))
    except (OSError, TypeError):
        return False


def _functions(item: pytest.Item) -> Iterator[Callable[..., object]]:
    """The test function and the functions of the fixtures it uses."""
    function = getattr(item, "function", None)
    if function is not None:
        yield function
    info = getattr(item, "_fixtureinfo", None)
    for definitions in info.name2fixturedefs.values() if info is not None else ():
        yield from (definition.func for definition in definitions)


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    for item in items:
        fixtures = set(getattr(item, "fixturenames", ()))
        if BROWSER_FIXTURES & fixtures:
            item.add_marker(pytest.mark.browser)
        if (SLOW_FIXTURES & fixtures or any(item.get_closest_marker(mark) for mark in SLOW_MARKS)
                or any(_starts_a_server(func) for func in _functions(item))):
            item.add_marker(pytest.mark.slow)


_WHOLLY_SLOW = re.compile(r"^pytestmark = (\[[^\]\n]*)?pytest\.mark\.(slow|browser|postgresql)\b", re.MULTILINE)
"""A module whose module-level mark makes every test of it slow (``slow``, ``browser`` or ``postgresql``, alone or in a
list)."""


def pytest_ignore_collect(collection_path: Path, config: pytest.Config) -> bool | None:
    """A run that leaves the slow tests out (``-m "not slow"``) does not import a module all of whose tests are slow:
    importing one can cost seconds in every worker (the fuzz module builds the whole OpenAPI document)."""
    if config.getoption("markexpr", "").replace(" ", "") != "notslow" or collection_path.suffix != ".py":
        return None
    if not collection_path.name.startswith("test_"):
        return None
    return bool(_WHOLLY_SLOW.search(collection_path.read_text(encoding="utf-8"))) or None


PRODUCT_HASHER = accounts._hasher
"""The argon2 parameters the product hashes passwords with (argon2-cffi's default, RFC 9106's low-memory choice)."""


@pytest.fixture(autouse=True, scope="session")
def cheap_password_hashes() -> Iterator[None]:
    """Passwords in the tests are hashed with argon2-cffi's cheapest argon2id parameters (its ``profiles.CHEAPEST``,
    meant for tests): the same algorithm and code path (hash, verify, the rehash check, the unknown user's dummy
    hash), without the 0.28 s of CPU the product's 64 MiB and three passes cost each hash and each sign-in (issue 29:
    the quick tests of the access and account modules took 48 s of CPU with them, 21 s without). The product's own
    parameters are pinned by tests/services/test_accounts.py; a server in a process of its own hashes as the
    product."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(accounts, "_hasher", PasswordHasher.from_parameters(profiles.CHEAPEST))
        yield


T = TypeVar("T")


@pytest.fixture
def patient_guard(monkeypatch: pytest.MonkeyPatch) -> None:
    """The drive guard waits 10 s (the most an API client may ask for) instead of 2 s for a keep-alive. For tests of
    a flow, not of the deadline: on a loaded 2-core machine two requests of one test can be more than 2 s apart (a
    clean-clone run quick-stopped the EtherCAT unit between its enable and its setpoint: "no keep-alive for 2 s").
    The 2 s deadline itself is tested in tests/services/test_drive_control.py, tests/web/test_moving_writes.py and
    tests/web/test_i18n_drive.py."""
    from drivebench.services.control import drive_guard

    monkeypatch.setattr(drive_guard, "KEEPALIVE_TIMEOUT_S", drive_guard.MAX_KEEPALIVE_S)


def frames_in_bus_order(wire: can.BusABC) -> list[can.Message]:
    """What a test's bus received, in bus order: by the frames' send stamps, not by the order its queue got them.
    python-can's virtual send stamps a frame as it starts, then puts a copy in each receiver's queue in turn: a sender
    held between its stamp and a put (a loaded machine) lets a frame sent later reach this queue first."""
    frames = []
    while (msg := wire.recv(0.2)) is not None:
        frames.append(msg)
    return sorted(frames, key=lambda msg: msg.timestamp)


def wait_until(condition: Callable[[], bool], seconds: float = 10.0) -> bool:
    """Poll ``condition`` until it holds or ``seconds`` pass (tests on a loaded machine poll with a deadline)."""
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(0.05)
    return bool(condition())


def wait_for_value(check: Callable[[], T], seconds: float = 10.0, what: str = "condition") -> T:
    """The first truthy value ``check`` gives within ``seconds`` (polled by :func:`wait_until`)."""
    seen: list[T] = []
    assert wait_until(lambda: bool(seen.append(check()) or seen[-1]), seconds), f"timed out waiting for {what}"
    return seen[-1]


def fresh_channel() -> str:
    """A virtual CAN channel no other test uses (python-can virtual channels are process-wide)."""
    return f"test-{os.getpid()}-{next(_channels)}-{uuid.uuid4().hex[:6]}"


@pytest.fixture(scope="session")
def migrated_sqlite(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A new SQLite file brought to the newest migration, once per worker: :func:`app_db_url` copies it (running the
    migrations took ~0.5 s of every app-starting test; the migrations themselves are tested on new databases in
    tests/services/test_database.py)."""
    path = tmp_path_factory.mktemp("migrated") / "drivebench.db"
    url = f"sqlite:///{path}"
    database.upgrade_to_head(url)
    database.dispose(url)
    return path


@pytest.fixture
def app_db_url(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, migrated_sqlite: Path) -> Iterator[str]:
    """The app's database is a fresh SQLite file of this test's own at the newest migration, as the app's start
    leaves a new one (apps created in the test use it)."""
    path = tmp_path / "drivebench.db"
    shutil.copyfile(migrated_sqlite, path)
    path.chmod(0o600)  # as the app makes its file (it holds password hashes)
    url = f"sqlite:///{path}"
    monkeypatch.setattr(app_settings, "database_url", url)
    yield url
    database.dispose(url)


@pytest.fixture(scope="session")
def postgres(tmp_path_factory: pytest.TempPathFactory) -> Iterator[PostgresCluster]:
    """One throw-away PostgreSQL cluster for the whole run (started on first use), shared by the run's xdist
    workers (each test has a database of its own in it)."""
    if os.environ.get("PYTEST_XDIST_WORKER") is None:
        try:
            cluster = PostgresCluster().start()
        except RuntimeError as exc:
            pytest.fail(str(exc))
        yield cluster
        cluster.stop()
        return
    try:
        with shared_cluster(tmp_path_factory.getbasetemp().parent) as cluster:
            yield cluster
    except RuntimeError as exc:
        pytest.fail(str(exc))


@pytest.fixture(params=["sqlite", pytest.param("postgresql", marks=pytest.mark.postgresql)])
def database_url(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[str]:
    """A fresh, empty database of this test's own: a SQLite file, and (the same test again) a PostgreSQL database."""
    if request.param == "sqlite":
        url = f"sqlite:///{tmp_path / 'db' / 'drivebench.db'}"
        yield url
        database.dispose(url)
        return
    cluster: PostgresCluster = request.getfixturevalue("postgres")
    url = cluster.new_database()
    yield url
    database.dispose(url)
    cluster.drop_database(url)


@pytest.fixture(scope="session")
def registry() -> ProfileRegistry:
    return ProfileRegistry()


@functools.cache
def shipped_switch_devices() -> SwitchDevices:
    """The calculator's devices: the ``switches`` sections of the shipped profiles (device_profiles/*.json)."""
    paths = sorted(app_settings.profiles_dir.glob("*.json"))
    return SwitchDevices(load_profile_file(path.read_bytes(), path.name) for path in paths)


@pytest.fixture
def channel() -> str:
    return fresh_channel()


@pytest.fixture
def demo_plant_file() -> PlantFile:
    return PlantFile.load(DEMO_PLANT)


@pytest.fixture
def plant(registry: ProfileRegistry, channel: str, demo_plant_file: PlantFile) -> Iterator[Plant]:
    """The demo plant's drives on a fresh virtual bus, without latency."""
    running = Plant(demo_plant_file, registry.get, bus=f"virtual:{channel}@500000", latency="0ms").start()
    yield running
    running.stop()


@pytest.fixture
def wire(channel: str) -> Iterator[can.BusABC]:
    """A python-can bus on the test channel that records every frame on the wire."""
    bus = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
    yield bus
    bus.shutdown()


@pytest.fixture(scope="module")
def module_demo_client() -> Iterator[TestClient]:
    """The real app with the demo plant on a fresh virtual bus, made once per module for its tests marked
    ``only_reads`` (see :func:`client`)."""
    app = create_app(plant_file=DEMO_PLANT, plant_bus=f"virtual:{fresh_channel()}@500000", latency="0ms")
    with TestClient(app) as test_client:
        yield test_client


@pytest.fixture
def client(request: pytest.FixtureRequest, channel: str) -> Iterator[TestClient]:
    """The real app with the demo plant on a fresh virtual bus (session id 'demo-plant'). A test marked
    ``only_reads`` (it changes no drive, node, session, account, lease or setting: reads, pages and refused requests)
    gets its module's one such app (:func:`module_demo_client`) with no cookies left from the test before: an app
    start is most of such a test's CPU (issue 29)."""
    if request.node.get_closest_marker("only_reads"):
        shared: TestClient = request.getfixturevalue("module_demo_client")
        shared.cookies.clear()
        yield shared
        return
    app = create_app(plant_file=DEMO_PLANT, plant_bus=f"virtual:{channel}@500000", latency="0ms")
    with TestClient(app) as test_client:
        yield test_client


@pytest.fixture
def demo_api(app_db_url: str) -> Iterator[TestClient]:
    """The real app with the demo plant on a fresh virtual bus (session id 'demo-plant') and a database of this
    test's own (the accounts the app reads from it are the app's own: ``AppState.accounts``)."""
    app = create_app(plant_file=DEMO_PLANT, plant_bus=f"virtual:{fresh_channel()}@500000", latency="0ms")
    with TestClient(app) as test_client:
        yield test_client


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


@contextlib.contextmanager
def serve_app(app: ASGIApp, start_timeout_s: float = 60.0, **config: object) -> Iterator[str]:
    """Run ``app`` in uvicorn on a free loopback port in a thread; yields its base URL, stops it on exit, also when
    it did not start in ``start_timeout_s`` (a server left starting ran on after the failed test, with its plant's
    and bus's threads). ``config`` goes to uvicorn (``ssl_certfile``/``ssl_keyfile`` serve https)."""
    sock = socket.socket()  # bound here, before the server starts: no other process (xdist worker) can take it
    sock.bind(("127.0.0.1", 0))
    port = int(sock.getsockname()[1])
    config.setdefault("timeout_graceful_shutdown", 5)  # a page left open keeps its websocket: stop anyway
    server = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=port, log_level="warning",
                                           **config))  # type: ignore[arg-type]
    thread = threading.Thread(target=server.run, kwargs={"sockets": [sock]}, daemon=True)
    thread.start()
    try:
        deadline = time.monotonic() + start_timeout_s  # the demo plant's start-up beside three workers took 20 s
        while not server.started and time.monotonic() < deadline:
            time.sleep(0.05)
        assert server.started, f"the test server did not start in {start_timeout_s:g} s"
        yield f"{'https' if config.get('ssl_certfile') else 'http'}://127.0.0.1:{port}"
    finally:
        server.should_exit = True
        thread.join(timeout=10)
        sock.close()


@pytest.fixture(scope="session")
def live_server() -> Iterator[str]:
    """uvicorn on a free loopback port with the demo plant, as `make run` starts it."""
    with serve_app(create_app(plant_file=DEMO_PLANT, plant_bus=f"virtual:{fresh_channel()}@500000")) as url:
        yield url


def _browser_scope(fixture_name: str, config: pytest.Config) -> str:
    """One Chromium per worker module under pytest-xdist, per run otherwise. Playwright's sync API keeps its event
    loop running on the main thread while it is open: a worker that ran a browser module and then a module that
    runs its own loop (asyncio.Runner, asyncio.run) failed that module's every test. Serially the browser modules
    come last (tests/web/); under xdist a worker takes modules in any order."""
    return "module" if os.environ.get("PYTEST_XDIST_WORKER") else "session"


@pytest.fixture(scope=_browser_scope)  # type: ignore[arg-type]
def browser() -> Iterator[object]:
    playwright_api = pytest.importorskip("playwright.sync_api")
    if not Path(CHROMIUM).exists():
        pytest.fail("Debian chromium is missing: `make test` installs it (apt-get install chromium)")
    with playwright_api.sync_playwright() as pw:
        instance = pw.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        yield instance
        instance.close()


@pytest.fixture
def page(browser: object) -> Iterator[object]:
    context = browser.new_context(viewport={"width": 1440, "height": 900})  # type: ignore[attr-defined]
    page = context.new_page()
    yield page
    context.close()


def screenshot(page: object, name: str) -> Path:
    ARTIFACTS.mkdir(exist_ok=True)
    path = ARTIFACTS / f"{name}.png"
    page.screenshot(path=str(path), full_page=True)  # type: ignore[attr-defined]
    return path
