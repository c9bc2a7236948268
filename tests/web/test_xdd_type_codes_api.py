"""EDS -> XDD -> EDS through the real API keeps a DataType the model reads as DOMAIN (INTEGER40, UNSIGNED56,
TIME_OF_DAY, TIME_DIFF): the case the outside corpus found (``benchmarks/outside_corpus.py``)."""

from __future__ import annotations

import pytest
from fastapi.testclient import TestClient

from drivebench.device.formats.eds_ini import parse_ini
from tests.device.test_xdd_type_codes import CODES, WIDE_TYPES

pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")


def test_an_eds_through_an_uploaded_xdd_comes_back_with_its_data_type_codes(api: TestClient) -> None:
    uploaded = api.post("/api/profiles", files={"file": ("wide.eds", WIDE_TYPES.encode())})
    assert uploaded.status_code == 201, uploaded.text
    xdd = api.get(f"/api/profiles/{uploaded.json()['id']}/xdd")
    assert xdd.status_code == 200
    again = api.post("/api/profiles", files={"file": ("wide-again.xdd", xdd.content)})
    assert again.status_code == 201, again.text
    eds = api.get(f"/api/profiles/{again.json()['id']}/eds", params={"regenerate": "true"})
    sections = parse_ini(eds.content.decode(), "back.eds")
    assert {index: int(sections[f"{index:04X}"].keys["datatype"].value, 16) for index in CODES} == CODES
