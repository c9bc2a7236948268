"""Prometheus metrics (prometheus_client) at ``GET /metrics``: HTTP requests and their latency by route, CAN frames
and error frames per session, SDO timeouts and aborts, open sessions, parameter jobs.

Who may read them: a scraper with the metrics token (``Authorization: Bearer <the token in
DRIVEBENCH_METRICS_TOKEN_FILE>``: the gate honours it on this route only), or someone signed in with the engineer
role (or an API token of that role). A server without sign-in serves them to this machine only, like everything
else."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator

from fastapi import APIRouter, Request, Response
from prometheus_client import CONTENT_TYPE_LATEST, CollectorRegistry, Counter, Histogram, generate_latest
from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily, Metric
from prometheus_client.registry import Collector
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from drivebench.errors import SDO_FAILURES
from drivebench.services.monitoring.monitor import monitor_for
from drivebench.services.params.jobs import JobManager
from drivebench.services.session_manager import SessionManager
from drivebench.web.deferred_route import DeferredRoute
from drivebench.web.metrics_token import METRICS_ROUTE
from drivebench.web.root import route_path

router = APIRouter(route_class=DeferredRoute, include_in_schema=False)


class Metrics:
    """One app's metrics (a registry of its own: several apps in one process, as in the tests, do not mix)."""

    def __init__(self, manager: Callable[[], SessionManager | None], jobs: Callable[[], JobManager | None]) -> None:
        self.registry = CollectorRegistry(auto_describe=True)
        self.requests = Counter("drivebench_http_requests", "HTTP requests answered, by route template and status",
                                ["method", "route", "status"], registry=self.registry)
        self.latency = Histogram("drivebench_http_request_duration_seconds", "Time to answer an HTTP request",
                                 ["method", "route"], registry=self.registry)
        self.registry.register(_Live(manager, jobs))

    def exposition(self) -> bytes:
        return generate_latest(self.registry)


class _Live(Collector):
    """What is read at each scrape: sessions, their bus counters, SDO failures, jobs."""

    def __init__(self, manager: Callable[[], SessionManager | None], jobs: Callable[[], JobManager | None]) -> None:
        self.manager = manager
        self.jobs = jobs

    def collect(self) -> Iterator[Metric]:
        manager = self.manager()
        sessions = manager.list() if manager is not None else []
        yield GaugeMetricFamily("drivebench_sessions", "Open bus sessions", value=len(sessions))
        frames = CounterMetricFamily("drivebench_bus_frames", "CAN frames seen on the session's bus since the "
                                     "monitor's last reset", labels=["session"])
        errors = CounterMetricFamily("drivebench_bus_error_frames", "CAN error frames since the monitor's last reset",
                                     labels=["session"])
        for session in sessions:
            if session.services is not None and session.network.capabilities.frames:  # not EtherCAT
                counted, error_frames = monitor_for(session).totals()
                frames.add_metric([session.id], counted)
                errors.add_metric([session.id], error_frames)
        yield frames
        yield errors
        sdo = CounterMetricFamily("drivebench_sdo_failures", "SDO requests that timed out or were aborted",
                                  labels=["kind"])
        for kind in ("timeout", "abort"):
            sdo.add_metric([kind], SDO_FAILURES[kind])
        yield sdo
        jobs = self.jobs()
        running = GaugeMetricFamily("drivebench_jobs", "Parameter jobs (read-all, set downloads) by state",
                                    labels=["state"])
        states: dict[str, int] = {}
        for job in jobs.list() if jobs is not None else []:
            states[str(job.state)] = states.get(str(job.state), 0) + 1
        for state, count in sorted(states.items()):
            running.add_metric([state], count)
        yield running


class RequestMetrics:
    """Counts every HTTP answer and its time, by the route's template (not the path: ids would make the labels
    unbounded)."""

    def __init__(self, app: ASGIApp, metrics: Metrics) -> None:
        self.app = app
        self.metrics = metrics

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        started = time.perf_counter()
        status = 500

        async def send_status(message: Message) -> None:
            nonlocal status
            if message["type"] == "http.response.start":
                status = int(message["status"])
            await send(message)

        try:
            await self.app(scope, receive, send_status)
        finally:
            route = scope.get("state", {}).get("route_template")  # the gate's decision (answered there or not)
            template = route if isinstance(route, str) else ("/static" if route_path(scope).startswith("/static/")
                                                              else "unmatched")
            method = str(scope.get("method", "GET"))
            self.metrics.requests.labels(method, template, str(status)).inc()
            self.metrics.latency.labels(method, template).observe(time.perf_counter() - started)


@router.get(METRICS_ROUTE)
async def metrics(request: Request) -> Response:
    """For the engineer role, or a scraper with the metrics token (web/metrics_token.py)."""
    collected: Metrics = request.app.state.metrics
    return Response(collected.exposition(), media_type=CONTENT_TYPE_LATEST)
