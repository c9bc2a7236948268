"""One value the drive will not give (an aborted read) marks that value on the Control tab; the panel stays (issue 33:
an EDS default the device cannot encode replaced the whole tab with its error)."""

from __future__ import annotations

from fastapi.testclient import TestClient

SESSION, SERVO = "demo-plant", 7
TAB = f"/ui/sessions/{SESSION}/nodes/{SERVO}/control"
FAULTS = f"/api/sessions/{SESSION}/simulator/nodes/{SERVO}/faults"


def test_an_aborted_mode_display_read_marks_that_value_and_keeps_the_panel(demo_api: TestClient) -> None:
    healthy = demo_api.get(TAB)
    assert healthy.status_code == 200
    assert 'id="control-panel"' in healthy.text and 'id="ctl-unread"' not in healthy.text

    faults = demo_api.put(FAULTS, json={"abort_code": "0x06090011", "abort_index": 0x6061})
    assert faults.status_code == 200, faults.text
    assert any("0x6061" in line for line in faults.json()["active"])
    tab = demo_api.get(TAB)
    assert tab.status_code == 200
    assert 'id="control-panel"' in tab.text, "the whole tab was replaced by the one read's error"
    assert 'id="ctl-unread"' in tab.text and '<span class="mono">0x6061</span>' in tab.text
    assert "0x06090011" in tab.text or "does not exist" in tab.text, "the reason in words"
    assert 'name="ctl-mode"' in tab.text, "the modes stay selectable"
    assert 'id="ctl-jog-how"' in tab.text and 'data-jog="1"' in tab.text

    status = demo_api.get(f"/api/sessions/{SESSION}/nodes/{SERVO}/control")
    assert status.status_code == 200, status.text
    assert status.json()["mode"] is None and "0x6061" in status.json()["unread"]


def test_a_device_that_aborts_every_read_still_gets_the_tab_error(demo_api: TestClient) -> None:
    """The status word itself is the panel: without it the tab says why, as before."""
    assert demo_api.put(FAULTS, json={"abort_code": "0x08000000"}).status_code == 200
    tab = demo_api.get(TAB)
    assert tab.status_code == 200
    assert 'id="control-panel"' not in tab.text and 'class="error"' in tab.text
