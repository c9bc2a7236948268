"""Routes whose FastAPI state is built at first use, not when their module is imported (issue 33).

FastAPI builds a route's state as the decorator runs: each parameter's pydantic field, the response model's field,
the endpoint's handler. For the ~300 routes that was 0.3-0.6 s of every server start's CPU before ``/api/health``
could answer, and a served request uses none of it: it reaches a route through its router's inclusion, and FastAPI
builds that inclusion's own (effective) copy of each route from the route's declared arguments
(``fastapi.routing._EffectiveRouteContext.from_api_route``; a worker thread builds them once the server listens,
``access_policy.build_effective_routes``, or the first request of a router). A :class:`DeferredRoute` keeps its
arguments and what matching needs (path, name, methods; the path's pattern is compiled at its first match) and
answers the inclusion's questions with what it was declared with; anything else (its dependant, response field,
handler: the OpenAPI document of a route not included, a test) builds it, as ``APIRoute`` builds it, at that first
use.
"""

from __future__ import annotations

import inspect
import threading
from enum import IntEnum
from typing import Any

from fastapi._form_limits import _validate_form_limits
from fastapi.routing import APIRoute
from starlette.routing import compile_path, get_name

_building = threading.RLock()
"""One build at a time: the worker thread and a request on the event loop may ask for the same route."""


def _sample_endpoint() -> None:
    return None


_COMPILED_PATH = frozenset({"path_regex", "path_format", "param_convertors"})
_KNOWN = frozenset({"path", "endpoint", "name", "methods", "include_in_schema"}) | _COMPILED_PATH
_BUILT: frozenset[str] = frozenset(vars(APIRoute("/", _sample_endpoint))) - _KNOWN
"""What ``APIRoute.__init__`` sets beyond what a deferred route knows at once."""
_DEFAULTS: dict[str, Any] = {name: parameter.default
                             for name, parameter in inspect.signature(APIRoute.__init__).parameters.items()
                             if parameter.kind is inspect.Parameter.KEYWORD_ONLY}
_DECLARED = frozenset({"response_model", "status_code", "tags", "dependencies", "summary", "description",
                       "response_description", "responses", "deprecated", "operation_id", "response_model_include",
                       "response_model_exclude", "response_model_by_alias", "response_model_exclude_unset",
                       "response_model_exclude_defaults", "response_model_exclude_none", "response_class",
                       "dependency_overrides_provider", "callbacks", "openapi_extra", "generate_unique_id_function",
                       "strict_content_type", "max_body_size", "form_limits", "stream_item_type"}) & _BUILT
"""What FastAPI's inclusion reads of a route to build its own copy (``_EffectiveRouteContext.from_api_route``):
until the route is built, these answer as declared (a response model or description not given stays so, and the
copy works it out from the endpoint as the route would); everything else in ``_BUILT`` builds the route."""


def _declared(arguments: dict[str, Any], name: str) -> Any:
    value = arguments.get(name, _DEFAULTS.get(name))
    if name in ("tags", "dependencies"):
        return list(value or [])
    if name == "responses":
        return dict(value or {})
    if name == "status_code" and isinstance(value, IntEnum):
        return int(value)
    if name == "form_limits":
        return _validate_form_limits(value)
    return value


class DeferredRoute(APIRoute):
    """An ``APIRoute`` built on first use of anything beyond its path, name, methods and declared arguments."""

    def __init__(self, path: str, endpoint: Any, **arguments: Any) -> None:
        self._deferred = (path, endpoint, arguments)
        self.path, self.endpoint = path, endpoint
        self.name = get_name(endpoint) if arguments.get("name") is None else arguments["name"]
        self.methods = {method.upper() for method in arguments.get("methods") or ["GET"]}
        self.include_in_schema = arguments.get("include_in_schema", True)

    def __getattr__(self, name: str) -> Any:
        if name in _COMPILED_PATH:  # at its first match (the gate tries the routes in order: /api/health first)
            self.path_regex, self.path_format, self.param_convertors = compile_path(self.path)
            return object.__getattribute__(self, name)
        if name not in _BUILT:
            raise AttributeError(name)
        with _building:
            deferred = self.__dict__.get("_deferred")
            if deferred is not None:
                path, endpoint, arguments = deferred
                if name in _DECLARED:
                    return _declared(arguments, name)
                del self.__dict__["_deferred"]  # built from here on (what the build reads, it has set)
                try:
                    APIRoute.__init__(self, path, endpoint, **arguments)
                except BaseException:
                    self._deferred = deferred
                    raise
        return object.__getattribute__(self, name)

    @property
    def built(self) -> bool:
        return "_deferred" not in self.__dict__
