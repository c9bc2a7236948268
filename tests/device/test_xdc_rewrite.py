"""A node's XDC written over the XDD its profile was read from (issue 34): the configured values as actualValue where
the file keeps values (an object attribute, or the parameter's ``actualValue`` element), the node id in
``deviceCommissioning``; every other line as the file has it."""

from __future__ import annotations

import pytest

from drivebench.device.formats.xdc_rewrite import rewrite_xdc
from drivebench.device.formats.xdd import read_xdd
from tests.device.test_xdd_rewrite import changed_lines
from tests.device.xdd_rewrite_corpus import ATTRIBUTES, PARAMETERS


@pytest.mark.parametrize(("content", "lines"), [
    (ATTRIBUTES, ['actualValue="3500" />', 'actualValue="-7" />',
                  '<deviceCommissioning nodeID="12" nodeName="Attr 8" networkNumber="1" networkName="" '
                  'CANopenManager="false" />']),
    (PARAMETERS, ['<q1:actualValue value="3500" />', '<q1:actualValue value="-7" />',
                  '<deviceCommissioning nodeID="12" nodeName="Editor device" networkNumber="1" networkName="" '
                  'CANopenManager="false" />'])], ids=["attributes", "parameters"])
def test_an_xdc_of_a_node_is_the_xdd_with_its_values_and_node_id(content: bytes, lines: list[str]) -> None:
    profile = read_xdd(content, source="in.xdd").profile
    written = rewrite_xdc(profile, content, "in.xdc", node_id=12, values={(0x2000, 0): 3500, (0x2001, 0): -7},
                          baud_kbit=None)
    added = [line[1:].strip() for line in changed_lines(content, written) if line.startswith("+")]
    assert all(any(line.endswith(want) for line in added) for want in lines), added
    removed = [line for line in changed_lines(content, written) if line.startswith("-")]
    assert len(removed) == (2 if content is ATTRIBUTES else 0), removed  # the two object lines got an attribute
    node = read_xdd(written, source="node.xdc").profile
    assert {(o.index, o.subindex): o.parameter_value for o in node.objects if o.parameter_value is not None} == {
        (0x2000, 0): 3500, (0x2001, 0): -7}
    assert node.extra_sections["DeviceComissioning"]["NodeID"] == "12"
    again = rewrite_xdc(node, written, "node.xdc", node_id=5, values={(0x2000, 0): 3500, (0x2001, 0): -7},
                        baud_kbit=500)
    changed = changed_lines(written, again)
    assert len(changed) == 2 and 'nodeID="5"' in changed[1] and 'actualBaudRate="500 Kbps"' in changed[1], changed
