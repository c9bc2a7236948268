"""The ``ethercat`` section of a device profile: what the device's EtherCAT slave offers beyond what every slave
has (ETG.1000.6), from its manual or its ESI file.

* ``esm_states``: the states of its EtherCAT state machine. Init, Pre-Operational, Safe-Operational and Operational
  every slave has; Bootstrap (firmware download by FoE) is optional: a device without it refuses a request for it
  with AL status code 0x0013 (the 8400 motec EtherCAT manual §7.3 lists that code: it has none). In an ESI file
  a ``BootStrap`` element in the device's ``Eeprom`` (the bootstrap mailbox) says the device has the state.
"""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator

from drivebench.i18n import _
from drivebench.protocol.ethercat.esm import MANDATORY_STATES, EsmState

EsmStateName = Literal["Init", "Pre-Operational", "Bootstrap", "Safe-Operational", "Operational"]
EVERY_SLAVE: list[EsmStateName] = ["Init", "Pre-Operational", "Safe-Operational", "Operational"]


class EthercatSection(BaseModel):
    model_config = ConfigDict(extra="forbid")

    esm_states: list[EsmStateName] = Field(
        default_factory=lambda: list(EVERY_SLAVE),
        description="The EtherCAT states the device has: Init, Pre-Operational, Safe-Operational and Operational "
                    "always, Bootstrap where the device has it.")
    source: str | None = None
    """Where the manual or ESI says so (``manual §7.3: AL status code 0x0013 ...``)."""

    @field_validator("esm_states")
    @classmethod
    def _every_slave_has_the_mandatory_states(cls, names: list[str]) -> list[str]:
        missing = [state.label for state in sorted(MANDATORY_STATES) if state.label not in names]
        if missing:
            raise ValueError(_("every EtherCAT slave has {states} (ETG.1000.6): list them in esm_states")
                             .format(states=", ".join(missing)))
        if len(set(names)) != len(names):
            raise ValueError(_("a state is listed twice in esm_states"))
        return names

    @property
    def states(self) -> frozenset[EsmState]:
        return frozenset(EsmState.parse(name) for name in self.esm_states)


DEFAULT = EthercatSection()
"""A profile without the section: the mandatory states, no Bootstrap."""
