"""Batch reads (``POST …/parameters:read``): many refs in one request, each with its value or its own error in words,
through the real API, the real simulator and SDO frames on a virtual CAN bus."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from drivebench.services.params.parameters import MAX_BATCH
from tests.web.test_parameters_api import PLANTS, Api, _start


@pytest.fixture
def api(tmp_path: Path, channel: str) -> Iterator[Api]:
    yield from _start(tmp_path, channel, PLANTS["8400"])


def _sdo_uploads(api: Api, node: int) -> list[tuple[int, int]]:
    """(index, subindex) of every SDO upload request the client sent to ``node`` (COB-ID 0x600 + node)."""
    return [(int.from_bytes(m.data[1:3], "little"), m.data[3]) for m in api.drain()
            if m.arbitration_id == 0x600 + node and m.data[0] == 0x40]


def test_batch_read_answers_every_ref_in_order_with_values_and_errors(api: Api) -> None:
    api.drain()
    refs = ["C00061", "0x1017.0", "0x2FFF.0", "C99999", "0x1018.1"]
    answer = api.client.post(api.url(4, "/parameters:read"), json={"refs": refs})
    assert answer.status_code == 200, answer.text
    items = answer.json()["items"]
    assert [item["ref"] for item in items] == refs
    by_ref = {item["ref"]: item for item in items}

    assert by_ref["C00061"]["ok"] and by_ref["C00061"]["value"]["raw"] == 43
    single = api.client.get(api.url(4, "/parameters/0x1017.0")).json()
    assert by_ref["0x1017.0"]["value"]["raw"] == single["raw"]
    assert by_ref["0x1018.1"]["ok"] and by_ref["0x1018.1"]["value"]["raw"] == \
        api.client.get(api.url(4, "/parameters/0x1018.1")).json()["raw"]

    aborted = by_ref["0x2FFF.0"]
    assert not aborted["ok"] and aborted["value"] is None
    assert aborted["error"]["abort_code"] == "0x06020000" and aborted["error"]["status"] == 404
    assert "0x2FFF" in aborted["error"]["detail"] and aborted["error"]["abort_text"]
    unknown = by_ref["C99999"]["error"]
    assert not by_ref["C99999"]["ok"] and "C99999" in unknown["detail"] and unknown["status"] == 404


def test_batch_read_sends_one_upload_per_ref_to_the_drive(api: Api) -> None:
    api.drain()
    answer = api.client.post(api.url(2, "/parameters:read"), json={"refs": ["0x1017.0", "0x1018.1", "0x1000.0"]})
    assert all(item["ok"] for item in answer.json()["items"])
    assert _sdo_uploads(api, 2) == [(0x1017, 0), (0x1018, 1), (0x1000, 0)]


def test_batch_read_refuses_in_words_what_it_cannot_do(api: Api) -> None:
    empty = api.client.post(api.url(4, "/parameters:read"), json={"refs": []})
    assert empty.status_code == 422 and "refs" in empty.json()["detail"]
    too_many = api.client.post(api.url(4, "/parameters:read"), json={"refs": ["C00061"] * (MAX_BATCH + 1)})
    assert too_many.status_code == 422 and str(MAX_BATCH) in too_many.text
    no_node = api.client.post(api.url(77, "/parameters:read"), json={"refs": ["C00061"]})
    assert no_node.status_code == 404
    assert no_node.headers["content-type"].startswith("application/problem+json")
    assert "Node 77" in no_node.json()["detail"]
