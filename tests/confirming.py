"""Confirm a moving request the way a careful API client does: send it, read the 428 problem's ``confirm_node`` and
``confirm_values`` (what the server will send), repeat the request with both.

A test that is about something else than the confirmation itself uses :func:`confirmed` (HTTP) or
:func:`confirmed_call` / :func:`confirmed_now` (a service called directly: the :class:`ConfirmationRequired` it raises
is answered the same way); a test of the confirmation checks the 428 and its fields on its own.
"""

from __future__ import annotations

import html
import json
import re
from collections.abc import Awaitable, Callable
from typing import Any, TypeVar

import httpx

from drivebench.errors import ConfirmationRequired
from drivebench.services.control.drive_guard import Confirmation

T = TypeVar("T")


def confirmation_of(problem: dict[str, Any]) -> tuple[object, object]:
    """The node and the values a 428 problem asks to be confirmed."""
    assert "confirm_node" in problem, f"a 428 names the node to confirm: {problem}"
    return problem["confirm_node"], problem.get("confirm_values")


def confirmed(client: Any, method: str, url: str, **kwargs: Any) -> httpx.Response:
    """``client.request(method, url, **kwargs)``; a 428 is answered once with the confirmation it asks for (as body
    fields when the request has a JSON body, form fields for a form, else the ``X-DriveBench-Confirm``/``-Values``
    headers). A request that names a node itself (``confirm`` in its body or form) is answered only when the 428 asks
    about that node, and one that sends ``"confirm": None`` on purpose is not answered: such a test sees the 428."""
    first = client.request(method, url, **kwargs)
    if first.status_code != 428:
        return first
    node, values = confirmation_of(first.json() if "json" in first.headers.get("content-type", "") else
                                   _from_fragment(first.text))
    body, form = kwargs.pop("json", None), kwargs.pop("data", None)
    named = (body if isinstance(body, dict) else form if isinstance(form, dict) else {}).get("confirm", ...)
    if named is None or (named is not ... and str(named) != str(node)):
        return first
    if isinstance(body, dict):
        return client.request(method, url, json={**body, "confirm": node, "confirm_values": values}, **kwargs)
    if isinstance(form, dict):
        form = {**form, "confirm": str(node), "confirm_values": json.dumps(values)}
        return client.request(method, url, data=form, **kwargs)
    headers = {**(kwargs.pop("headers", None) or {}), "X-DriveBench-Confirm": str(node)}
    if values is not None:
        headers["X-DriveBench-Confirm-Values"] = json.dumps(values, separators=(",", ":"), sort_keys=True)
    return client.request(method, url, json=body, data=form, headers=headers, **kwargs)


def _from_fragment(text: str) -> dict[str, Any]:
    """A page's 428 (an htmx error fragment): the node and values its data attributes carry, as app.js reads them."""
    found = re.search(r'data-confirm-node="([^"]*)" data-confirm-values="([^"]*)"', text)
    assert found, f"a 428 fragment names the node and values to confirm: {text[:300]}"
    return {"confirm_node": html.unescape(found.group(1)), "confirm_values": json.loads(html.unescape(found.group(2)))}

def _answer(exc: ConfirmationRequired, node: object) -> Confirmation:
    assert node is None or str(exc.node) == str(node), f"asked to confirm node {exc.node}, the test meant {node}"
    return Confirmation(exc.node, exc.values)


async def confirmed_call(call: Callable[..., Awaitable[T]], *args: Any, confirm: object = None, **kwargs: Any) -> T:
    """``await call(*args, **kwargs)`` without a confirmation; its :class:`ConfirmationRequired` is answered once with
    the node and values it names (``confirm``, when given, is the node the test expects to be asked about)."""
    try:
        return await call(*args, **kwargs)
    except ConfirmationRequired as exc:
        return await call(*args, confirm=_answer(exc, confirm), **kwargs)


def confirmed_now(call: Callable[..., T], *args: Any, confirm: object = None, **kwargs: Any) -> T:
    """:func:`confirmed_call` for a service that checks the confirmation before it returns (a job it starts)."""
    try:
        return call(*args, **kwargs)
    except ConfirmationRequired as exc:
        return call(*args, confirm=_answer(exc, confirm), **kwargs)
