"""Confirm a moving request the way a careful API client does: send it, read the 428 problem's ``confirm_node`` and
``confirm_values`` (what the server will send), repeat the request with both.

A test that is about something else than the confirmation itself uses :func:`confirmed`; a test of the confirmation
checks the 428 and its fields on its own.
"""

from __future__ import annotations

import json
from typing import Any

import httpx


def confirmation_of(problem: dict[str, Any]) -> tuple[object, object]:
    """The node and the values a 428 problem asks to be confirmed."""
    assert "confirm_node" in problem, f"a 428 names the node to confirm: {problem}"
    return problem["confirm_node"], problem.get("confirm_values")


def confirmed(client: Any, method: str, url: str, **kwargs: Any) -> httpx.Response:
    """``client.request(method, url, **kwargs)``; a 428 is answered once with the confirmation it asks for (as body
    fields when the request has a JSON body, else as the ``X-DriveBench-Confirm``/``-Values`` headers)."""
    first = client.request(method, url, **kwargs)
    if first.status_code != 428:
        return first
    node, values = confirmation_of(first.json())
    body = kwargs.pop("json", None)
    if isinstance(body, dict):
        body = {**body, "confirm": node, "confirm_values": values}
        return client.request(method, url, json=body, **kwargs)
    headers = {**kwargs.pop("headers", {}), "X-DriveBench-Confirm": str(node)}
    if values is not None:
        headers["X-DriveBench-Confirm-Values"] = json.dumps(values, separators=(",", ":"), sort_keys=True)
    return client.request(method, url, json=body, headers=headers, **kwargs)
