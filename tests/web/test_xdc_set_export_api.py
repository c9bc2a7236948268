"""A parameter set of a profile uploaded as an XDD exported as XDC (issue 34): the upload with the set's values as
actualValue and the node id in deviceCommissioning, every other line as uploaded, in both CiA 311 layouts."""

from __future__ import annotations

import pytest
from fastapi.testclient import TestClient

from drivebench.device.formats.xdd import read_xdd
from tests.device.test_xdd_rewrite import changed_lines
from tests.device.xdd_rewrite_corpus import ATTRIBUTES, PARAMETERS

SETS = "/api/parameter-sets"


@pytest.mark.parametrize(("name", "content"), [("attributes.xdd", ATTRIBUTES), ("parameters.xdd", PARAMETERS)])
def test_the_xdc_of_a_set_is_the_uploaded_xdd_with_its_values(demo_api: TestClient, name: str,
                                                              content: bytes) -> None:
    uploaded = demo_api.post("/api/profiles", files={"file": (name, content)})
    assert uploaded.status_code == 201, uploaded.text
    profile_id = uploaded.json()["id"]
    csv = "code,name,value,unit\n0x2000,,3500,\n0x2001,,-7,\n"
    imported = demo_api.post(f"{SETS}/import", files={"file": ("set.csv", csv.encode())},
                             data={"profile_id": profile_id, "name": "Line 2"})
    assert imported.status_code == 201, imported.text
    set_id = imported.json()["set"]["id"]
    exported = demo_api.get(f"{SETS}/{set_id}/export", params={"format": "xdc"})
    assert exported.status_code == 200 and exported.headers["content-type"].startswith("application/xml")
    node = read_xdd(exported.content, source="line2.xdc").profile
    assert {(o.index, o.subindex): o.parameter_value for o in node.objects if o.parameter_value is not None} == {
        (0x2000, 0): 3500, (0x2001, 0): -7}
    changed = changed_lines(content, exported.content)
    added = [line for line in changed if line.startswith("+")]
    assert len(added) == 3 and any("deviceCommissioning" in line for line in added), changed
    assert len(changed) == (5 if content is ATTRIBUTES else 3), changed  # nothing else of the upload changed
