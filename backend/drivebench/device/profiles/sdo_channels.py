"""The ``sdo_channels`` section of a device profile: additional SDO servers the tool may switch on to read faster.

The tool activates such a channel itself (writing its server parameter object 0x1200 + n - 1, not saved on the
device) when the object is unset or invalid, and spreads a read-all over it. The COB-IDs follow the device's
rule: ``rx_base + node id`` (client -> server) and ``tx_base + node id`` (server -> client).
"""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field

from drivebench.device.profiles.hex_int import HexInt

SDO1_RX_BASE = 0x600
"""CiA 301 default SDO client -> server identifier of a node: 0x600 + node id."""


class SdoServerChannel(BaseModel):
    """One additional SDO server channel and the identifier rule the manual gives for it."""

    model_config = ConfigDict(extra="forbid")

    number: int = Field(2, ge=2, le=128)
    """SDO server number: its parameters are object 0x1200 + number - 1 (SDO2: 0x1201)."""
    rx_base: HexInt = Field(ge=0, le=0x7FF)
    tx_base: HexInt = Field(ge=0, le=0x7FF)
    max_node_id: int = Field(127, ge=1, le=127)
    """Nodes above it have no such channel: their identifiers would leave the range the manual gives."""
    source: str | None = None
    """Where the manual gives the rule."""

    @property
    def parameter_index(self) -> int:
        return 0x1200 + self.number - 1

    def cob_ids(self, node_id: int) -> tuple[int, int]:
        """(client -> server, server -> client) of ``node_id``."""
        return self.rx_base + node_id, self.tx_base + node_id

    def clashes_with(self, node_id: int) -> int:
        """The node id whose default SDO the channel's request identifier is (0x640 + 5 is node 69's 0x600 + 69)."""
        return self.cob_ids(node_id)[0] - SDO1_RX_BASE
