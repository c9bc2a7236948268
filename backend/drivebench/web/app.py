"""The FastAPI application: JSON API under /api, HTML pages, websockets under /ws."""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import AsyncIterator
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

from fastapi import FastAPI
from fastapi.staticfiles import StaticFiles

from drivebench import __version__
from drivebench.config import settings
from drivebench.device.profiles.loader import ProfileRegistry
from drivebench.services.profiles import loading as profiles_loading
from drivebench.services.scope import restore_record
from drivebench.services.scope import runs as scope_runs
from drivebench.services.session_manager import SessionManager
from drivebench.services.sets import set_jobs
from drivebench.services.sets.parameter_sets import ParameterSetStore
from drivebench.services.storage.database import upgrade_to_head
from drivebench.services.users import audit
from drivebench.services.users.accounts import Accounts
from drivebench.services.users.sharing import ShareLinks
from drivebench.simulator.plant import Plant, PlantFile
from drivebench.web import access, access_policy, first_answer, heap, language, problems, shared_routes
from drivebench.web import metrics as metrics_api
from drivebench.web.api import accounts as accounts_api
from drivebench.web.api import diagnostics, health, parameter_sets, parameters, pdo, profiles, sessions, tools
from drivebench.web.api import drive_control as drive_control_api
from drivebench.web.api import line_projects as line_projects_api
from drivebench.web.api import line_wizard as line_wizard_api
from drivebench.web.api import lss as lss_api
from drivebench.web.api import monitor as monitor_api
from drivebench.web.api import program as program_api
from drivebench.web.api import scope as scope_api
from drivebench.web.api import simulator as simulator_api
from drivebench.web.gate import RequestGate
from drivebench.web.metrics import Metrics, RequestMetrics
from drivebench.web.pages import accounts as accounts_page
from drivebench.web.pages import line_projects as line_projects_page
from drivebench.web.pages import line_wizard as line_wizard_page
from drivebench.web.pages import lss as lss_page
from drivebench.web.pages import monitor as monitor_page
from drivebench.web.pages import node as node_page
from drivebench.web.pages import node_control, node_diagnostics
from drivebench.web.pages import node_factory as node_factory_page
from drivebench.web.pages import node_pdo as node_pdo_page
from drivebench.web.pages import parameter_sets as parameter_sets_page
from drivebench.web.pages import plant as plant_page
from drivebench.web.pages import profiles as profiles_page
from drivebench.web.pages import remote as remote_page
from drivebench.web.pages import scope as scope_page
from drivebench.web.pages import sets_audit as sets_audit_page
from drivebench.web.pages import tools as tools_page
from drivebench.web.request_ids import RequestIds
from drivebench.web.state import AppState
from drivebench.web.ws import drive_control as drive_control_ws
from drivebench.web.ws import jobs as jobs_ws
from drivebench.web.ws import monitor as monitor_ws
from drivebench.web.ws import nodes as nodes_ws
from drivebench.web.ws import process_data as process_data_ws
from drivebench.web.ws import remote as remote_ws
from drivebench.web.ws import scope as scope_ws

log = logging.getLogger(__name__)

UPLOADS_GRACE_S = 0.5
"""How long the start waits for a few stored uploads (without holding the event loop): they are all there at the
first answer, as before."""
GRACE_UPLOADS = 20
"""The most stored upload files the start waits for: a folder of hundreds loads after the server listens, and
waiting for its first part only put off the first answer while the loading thread took the CPU the start needed
(issue 33)."""

# One line per router: screens grow without touching anything else here. FastAPI matches a request router by
# router, so the routes a client polls come first (the parameter reads: one router walked instead of eight, ~0.3 ms
# per read on this machine); none of their paths is a path of a router after them (benchmarks/RESULTS.md).
API_ROUTERS = [health.router, parameters.router, monitor_api.router, sessions.router, profiles.router,
               diagnostics.router, tools.router, tools.planned_router, pdo.router, parameter_sets.router,
               drive_control_api.router, accounts_api.router, simulator_api.router, metrics_api.router,
               line_projects_api.router, lss_api.router, scope_api.router, program_api.router,
               line_wizard_api.router]
PAGE_ROUTERS = [language.router, node_diagnostics.router, node_pdo_page.router, monitor_page.router, plant_page.router,
                node_control.router, node_page.router, node_factory_page.router, profiles_page.router,
                remote_page.router, tools_page.router, sets_audit_page.router, parameter_sets_page.router,
                accounts_page.router, line_projects_page.router, lss_page.router, scope_page.router,
                line_wizard_page.router]
WS_ROUTERS = [monitor_ws.router, nodes_ws.router, jobs_ws.router, remote_ws.router, process_data_ws.router,
              drive_control_ws.router, scope_ws.router]


async def start_plant(state: AppState, plant_path: Path, *, bus: str | None = None,
                      latency: str | None = None) -> None:
    """Start a simulated plant and open a session on its bus with its nodes."""
    plant_file = PlantFile.load(plant_path)
    slaves = plant_file.ethercat.slaves if plant_file.ethercat is not None else []
    await profiles_loading.profiles_known(state.registry, [*(n.profile for n in plant_file.nodes),
                                                           *(s.profile for s in slaves)])
    plant = await asyncio.to_thread(lambda: Plant(plant_file, state.registry.get, bus=bus, latency=latency).start())
    session = await state.manager.open(plant.spec, name=plant_file.name, simulated=True)
    state.plants[session.id] = plant
    for node in plant_file.nodes:
        if node.node_id in plant.nodes:  # a device without a node ID joins the session once addressed (LSS)
            session.add_node(node.node_id, node.profile, node.name)
    if plant_file.ethercat is not None:  # a second session: the slaves behind a simulated master's gateway
        line = plant_file.ethercat
        gateway = await asyncio.to_thread(line.start, state.registry.get, latency=latency)
        try:
            ethercat = await state.manager.open(gateway.spec, name=line.name, simulated=True)
        except BaseException:
            await asyncio.to_thread(gateway.stop)
            raise
        state.gateways[ethercat.id] = gateway


def _running(app: FastAPI, part: str) -> Any:
    """A part of the running app's state (None before its start)."""
    state = getattr(app.state, "drivebench", None)
    return getattr(state, part) if isinstance(state, AppState) else None


def _settle_heap_once_loaded(uploads: asyncio.Task[None]) -> asyncio.Task[None] | None:
    """``heap.settle`` once the stored uploads are read: they live as long as the server too, so the frozen heap
    holds them, and the first answers do not wait for the full collection over everything the start made (about a
    fifth of a second of CPU, issue 33). Settled at once when they are read already (a task when they are not)."""
    if uploads.done():
        heap.settle()
        return None

    async def settle() -> None:
        await asyncio.wait({uploads})
        heap.settle()

    return asyncio.create_task(settle())


def create_app(*, demo: bool = False, plant_file: Path | None = None, buses: list[str] | None = None,
               latency: str | None = None, plant_bus: str | None = None, hsts: bool | None = None,
               settle_heap: bool = False) -> FastAPI:
    """``settle_heap``: a server process of its own (``drivebench serve``) freezes what start-up made (``heap``)."""
    share_links = ShareLinks()
    sign_ins = access.SignIns(Accounts(), access.Sessions())  # the gate's and the routes' (AppState) alike
    answer_signal = first_answer.AnswerSignal()

    @contextlib.asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        asyncio.get_running_loop().set_default_executor(ThreadPoolExecutor(64, thread_name_prefix="bus-work"))
        await asyncio.to_thread(upgrade_to_head)  # the database schema (settings.database_url) to the newest
        await asyncio.to_thread(set_jobs.close_interrupted, ParameterSetStore())
        answered = answer_signal.arm()
        registry = await asyncio.to_thread(ProfileRegistry, defer_uploads=True)  # the shipped ones
        uploads = asyncio.create_task(profiles_loading.load_in_background(registry))  # the stored ones, after
        few = registry.upload_progress()[1] <= GRACE_UPLOADS
        begin: asyncio.Task[None] | None = None
        if few or demo or plant_file or buses:  # a plant's nodes may name stored uploads; buses make garbage
            registry.begin_uploads()  # (the held collector waits for the uploads) before anyone asks
        else:  # a large folder: once the first answer is sent, or as soon as a request needs a stored upload
            begin = first_answer.after_answer(answered, registry.begin_uploads)
        if few:  # a small folder is read before the first answer
            await asyncio.wait({uploads}, timeout=UPLOADS_GRACE_S)
        manager = SessionManager(registry, sdo_timeout_s=settings.sdo_timeout_s, sdo_retries=settings.sdo_retries,
                                 write_audits=[audit.AuditLog()])  # every write the tool sends is logged
        state = AppState(registry, manager, share_links=share_links, accounts=sign_ins.accounts,
                         cookie_sessions=sign_ins.sessions)
        app.state.drivebench = state
        access_policy.precompute(app)  # every route's access decisions, before the first request
        if demo or plant_file:
            await start_plant(state, plant_file or settings.plants_dir / "demo.json", bus=plant_bus,
                              latency=latency)
        for bus in buses or []:
            await manager.open(bus)
        await restore_record.restore_leftovers(manager)  # what recordings a killed server left mapped on the nodes
        settling = _settle_heap_once_loaded(uploads) if settle_heap else None
        routes_built = first_answer.after_answer(
            answered, lambda: asyncio.to_thread(access_policy.build_effective_routes, app))
        try:
            yield
        finally:
            for session in manager.list():  # a running scope recording ends and keeps what it captured
                await scope_runs.close(session)
            registry.stop_loading()
            await manager.close_all()
            for plant in state.plants.values():
                await asyncio.to_thread(plant.stop)
            for gateway in state.gateways.values():
                await asyncio.to_thread(gateway.stop)
            if begin is not None:
                await first_answer.end(begin, answered)
            await uploads
            if settling is not None:
                await settling
            await first_answer.end(routes_built, answered)

    docs = settings.api_docs  # their scripts come from a CDN: development only
    app = FastAPI(title="DriveBench", version=__version__, lifespan=lifespan, docs_url="/docs" if docs else None,
                  redoc_url="/redoc" if docs else None,
                  description="Commissioning of CANopen drives: parameters, PDOs, NMT, diagnostics.")
    problems.install(app)
    access.install(app)  # the roles in the OpenAPI document
    shared_routes.include(app, API_ROUTERS + PAGE_ROUTERS + WS_ROUTERS)  # built once per process
    # One pass for the language, security headers, body limit, share-link scope, host/origin, sign-in, roles, CSRF
    # and the lean answers.
    app.add_middleware(RequestGate, links=share_links, sign_ins=sign_ins, limit_bytes=settings.max_upload_bytes,
                       batch_bytes=settings.max_batch_upload_bytes,
                       hsts=settings.hsts if hsts is None else hsts)
    app.add_middleware(first_answer.FirstAnswer, signal=answer_signal)  # around the gate: a refusal answers too
    app.state.metrics = metrics = Metrics(lambda: _running(app, "manager"), lambda: _running(app, "jobs"))
    app.add_middleware(RequestMetrics, metrics=metrics)  # around the gate: its refusals are answers too
    app.add_middleware(RequestIds)  # outermost: every log record of a request, refusals included, names it
    app.mount("/static", StaticFiles(directory=settings.frontend_dir / "static"), name="static")
    return app
