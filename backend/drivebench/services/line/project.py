"""A line project: the whole line in one file a person can keep, diff and mail (issue 32).

Per node: the planned node (device, node id, bit rate, channels), the identity the boot-up check expects (device type,
vendor, product, revision range, serial where known), whether the line needs it (mandatory, CiA 302-2 0x1F81 bit 3),
the profile (id + SHA-256 of its content, an uploaded one embedded), the parameter set (name, set id on the server
it came from, the values) and the PDO set-up (the values of 0x1400-0x1BFF) and the firmware version expected.
Keys come in a fixed order (the fields' order; values in the profile's order) so two exports diff line by line.
File formats (JSON, lely-style YAML) are in :mod:`drivebench.services.line.files`.
"""

from __future__ import annotations

import re
from typing import Annotated, Literal

from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, PlainSerializer

from drivebench.errors import NotFound
from drivebench.i18n import _
from drivebench.services.planning.planner import CableInput, NetworkPlan, PlannedNode

SCHEMA_VERSION = 1
Raw = int | float | str
Values = dict[str, Raw]


def _number(value: object) -> object:
    """``"0x0000003B"`` / ``"59"`` / ``59`` -> 59 (hex is how the manuals and EDS files write identities)."""
    if isinstance(value, str) and re.fullmatch(r"\s*(0[xX][0-9a-fA-F]+|\d+)\s*", value):
        return int(value.strip(), 0)
    return value


Hex32 = Annotated[int, BeforeValidator(_number), Field(ge=0, le=0xFFFFFFFF),
                  PlainSerializer(lambda value: f"0x{value:08X}", return_type=str)]
"""A 32-bit identity value, written ``0x0000003B`` in the file."""

PDO_INDICES = range(0x1400, 0x1C00)
"""RPDO/TPDO communication and mapping parameters (CiA 301)."""


class ExpectedIdentity(BaseModel):
    """What the boot-up check compares (CiA 302-2: 0x1F84 device type, 0x1F85 vendor, 0x1F86 product, 0x1F87
    revision, 0x1F88 serial). None: not checked."""

    model_config = ConfigDict(extra="forbid")

    device_type: Hex32 | None = None
    vendor_id: Hex32 | None = None
    product_code: Hex32 | None = None
    revision_min: Hex32 | None = None
    revision_max: Hex32 | None = None
    """The highest revision the line accepts (None: no upper bound; a single revision: min = max)."""
    serial: Hex32 | None = None
    """Known from the device's label or an LSS inquiry; None: any serial."""


class EmbeddedProfile(BaseModel):
    """An uploaded profile's file, so a fresh server can load it (built-in profiles are only named)."""

    model_config = ConfigDict(extra="forbid")

    filename: str
    content: str


class ProfileRef(BaseModel):
    model_config = ConfigDict(extra="forbid")

    id: str
    sha256: str
    """Of the profile's content (its file's bytes; a JSON profile's JSON): a changed profile is noticed."""
    embedded: EmbeddedProfile | None = None


class ProjectSet(BaseModel):
    model_config = ConfigDict(extra="forbid")

    name: str = Field(min_length=1, max_length=200)
    set_id: int | None = None
    """The stored set on the server the project was made on / imported into (a reference; the values are here)."""
    values: Values = Field(default_factory=dict)
    """Raw values by canonical ref, without the PDO set-up (that is the node's ``pdo``)."""


class ProjectNode(BaseModel):
    model_config = ConfigDict(extra="forbid")

    node_id: int = Field(ge=1, le=127)
    name: str = Field("", max_length=200)
    device: str = Field(max_length=200)
    """As in the planned network: a switches key, an alias or a profile id."""
    baud_kbit: int
    mandatory: bool = True
    channels: list[str] | None = None
    pdo_ids: str = "canopen"
    identity: ExpectedIdentity = Field(default_factory=ExpectedIdentity)
    profile: ProfileRef | None = None
    parameter_set: ProjectSet | None = None
    pdo: Values = Field(default_factory=dict)
    firmware_version: str | None = None
    """The firmware the line expects (program download, issue 32 step 3, compares it)."""

    def planned(self) -> PlannedNode:
        return PlannedNode(name=self.name, device=self.device, node_id=self.node_id, baud_kbit=self.baud_kbit,
                           channels=self.channels, pdo_ids=self.pdo_ids)

    def set_values(self) -> Values:
        """The parameter set and the PDO set-up as one set's values."""
        return {**(self.parameter_set.values if self.parameter_set else {}), **self.pdo}


class MasterConfig(BaseModel):
    model_config = ConfigDict(extra="forbid")

    node_id: int = Field(1, ge=1, le=127)
    """The master's own node id (lely's ``master.node_id``)."""


class LineProject(BaseModel):
    model_config = ConfigDict(extra="forbid")

    schema_version: Literal[1] = 1
    """The file format's version (:data:`SCHEMA_VERSION`); a later format is refused, not guessed."""
    name: str = Field("Line project", min_length=1, max_length=200)
    master: MasterConfig = Field(default_factory=MasterConfig)
    cable: CableInput | None = None
    nodes: list[ProjectNode] = Field(default_factory=list)

    def plan(self) -> NetworkPlan:
        """The planned network the project extends."""
        return NetworkPlan(name=self.name, nodes=[node.planned() for node in self.nodes], cable=self.cable)

    def node(self, node_id: int) -> ProjectNode:
        for node in self.nodes:
            if node.node_id == node_id:
                return node
        raise NotFound(_("Node {node} is not in the line project '{name}'.").format(node=node_id, name=self.name))

    def sorted(self) -> LineProject:
        """Nodes by node id (the file's stable order)."""
        return self.model_copy(update={"nodes": sorted(self.nodes, key=lambda n: n.node_id)})
