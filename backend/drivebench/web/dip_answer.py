"""The DIP-switch calculator's answer: the switches or node id/baud rate, and the COB-IDs the node then uses.
Shared by the tools API and the Tools page."""

from __future__ import annotations

import contextlib

from pydantic import BaseModel

from drivebench.device.calculators.cobids import STANDARD_IDS, CobId, PdoIds, cob_ids, uses_alternative
from drivebench.device.calculators.dip import DipResult, SwitchDevice
from drivebench.device.calculators.switches import SwitchesSection
from drivebench.errors import DriveBenchError


class DipAnswer(BaseModel):
    family: SwitchesSection
    """The device's ``switches`` section (its profile's)."""
    result: DipResult
    cob_ids: list[CobId]
    """COB-IDs the node uses (empty when the node id is not known, e.g. the parameter value is not given)."""
    cob_id_notes: list[str]


def dip_answer(device: SwitchDevice, result: DipResult, pdo_ids: PdoIds = STANDARD_IDS) -> DipAnswer:
    spec = device.spec
    ids: list[CobId] = []
    if result.node_id is not None:
        with contextlib.suppress(DriveBenchError):  # a parameter value outside the range: no COB-IDs to show
            ids = cob_ids(spec, result.node_id, pdo_ids=pdo_ids if uses_alternative(spec, pdo_ids) else STANDARD_IDS)
    return DipAnswer(family=spec, result=result, cob_ids=ids, cob_id_notes=spec.cob_ids.notes)
