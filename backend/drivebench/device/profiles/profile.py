"""The device profile model: what the tool knows about one drive type.

A profile has three parts:

* identity (vendor id, product code, names, the manual it was built from),
* ``objects``: CANopen object dictionary entries addressed by index/subindex (0x1000 ..., CiA 402 0x6040 ...),
* ``parameters``: the vendor parameter layer (Lenze codes ``C00088``, Siemens ``P2040``/``r2054``), addressed by
  code and subcode; the family's ``addressing`` rule maps them onto CANopen indices.

All limits and defaults are in **engineering units** (what the manual prints, e.g. 10.20 A); ``factor`` converts:
``raw = round(value * factor)`` (Lenze: factor 100 = two decimals; EMF2178IB FIX32: factor 10000).
JSON files in ``device_profiles/`` are this model serialised; ``/api/profiles/schema`` publishes its JSON schema.
"""

from __future__ import annotations

from enum import StrEnum
from typing import Annotated, ClassVar, Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator

from drivebench.device.calculators.switches import SwitchesSection
from drivebench.device.drive.control import ControlSection, Sequence
from drivebench.device.drive.faults import FaultsSection
from drivebench.device.profiles.abort_texts import AbortTexts
from drivebench.device.profiles.commands import CommandsSection
from drivebench.device.profiles.ethercat_section import EthercatSection
from drivebench.device.profiles.hex_int import HexInt
from drivebench.device.profiles.pdo_rules import PdoRules
from drivebench.device.profiles.sdo_channels import SdoServerChannel
from drivebench.i18n import N_, Text
from drivebench.protocol.datatypes import DataType

Number = int | float
Value = int | float | str


class Access(StrEnum):
    """CiA 306 access types."""

    RO = "ro"
    WO = "wo"
    RW = "rw"
    RWR = "rwr"
    RWW = "rww"
    CONST = "const"

    @property
    def readable(self) -> bool:
        return self is not Access.WO

    @property
    def writable(self) -> bool:
        return self in (Access.WO, Access.RW, Access.RWR, Access.RWW)


class StillValue(BaseModel):
    """A written raw value that cannot make the drive move: ``raw & mask == value`` (no mask: the whole value)."""

    model_config = ConfigDict(extra="forbid")

    value: HexInt
    mask: HexInt | None = None
    meaning: str | None = None
    """What such a value does (``quick stop``, ``controller inhibit``)."""


class Motion(BaseModel):
    """Marks an object or parameter whose write can make the drive move: a control word, a setpoint, the mode of
    operation, a command/setpoint source selection, an NMT self-start object. Such a write needs the confirmation
    naming the node and arms the keep-alive guard, unless the value is one of ``still`` (a control word that only
    disables or quick-stops, a velocity setpoint of 0). CiA 402 objects are marked by the standard even when a
    profile does not say so (:mod:`drivebench.device.drive.motion`)."""

    model_config = ConfigDict(extra="forbid")

    kind: Literal["control_word", "setpoint", "mode", "source", "start"]
    still: list[StillValue] = Field(default_factory=list)
    """Values that cannot move the drive; empty: every write may move it. Only values that cannot move it from any
    state count (:mod:`drivebench.device.drive.motion`: a control word's must hold a blocking bit of the profile's
    control section; a setpoint's is 0); a profile cannot make a standard object's mark weaker."""
    source: str | None = None
    """Where the manual says so (edition, chapter, page)."""


class WriteGate(BaseModel):
    """The device accepts a write of this entry only while another parameter holds one of ``values`` (MICROMASTER:
    motor data only while P0010 = 1); otherwise it answers the SDO abort ``abort_code``."""

    model_config = ConfigDict(extra="forbid")

    ref: str
    values: list[int]
    abort_code: HexInt
    source: str | None = None


class WriteEffect(BaseModel):
    """What the device does itself when this entry is written with one of ``values`` (any value when empty): it sets
    the parameters of ``sets`` (MICROMASTER: P3900 = 1...3 ends quick commissioning, P0010 back to 0)."""

    model_config = ConfigDict(extra="forbid")

    values: list[int] = Field(default_factory=list)
    sets: dict[str, Value]
    source: str | None = None


class Entry(BaseModel):
    """Fields shared by CANopen objects and vendor parameters: one readable/writable value."""

    model_config = ConfigDict(extra="forbid", use_enum_values=False)

    name: str
    name_de: str | None = None
    """The German name as the vendor's German manual prints it: the German UI shows it instead of ``name``."""
    data_type: DataType
    access: Access = Access.RW
    unit: str | None = None
    factor: Number = 1
    """raw = round(value * factor); 1 for plain integers, 100 for two decimals, 10000 for Lenze FIX32."""
    min: Number | None = None
    max: Number | None = None
    default: Value | None = None
    selection: dict[int, str] = Field(default_factory=dict)
    """Selection list: raw value -> meaning (C00351: 0 -> '500 kbit/s')."""
    bits: dict[int, str] = Field(default_factory=dict)
    """Bit-coded words: bit number -> meaning."""
    hex: bool = False
    """Shown in hexadecimal (a vendor code holding a COB-ID or an identity); CiA 301's COB-IDs, identity and mapping
    entries and bit-coded words are without it (:mod:`drivebench.device.profiles.number_base`)."""
    pdo_mappable: bool = False
    reset_required: bool = False
    """Takes effect only after reset node (C00350, C00351 ...)."""
    group: str | None = None
    description: str | None = None
    description_de: str | None = None
    """The short help text in German: the German UI shows it instead of ``description``."""
    source: str | None = None
    """Where range, default, unit and selection come from (document, edition, page or table), and what no source
    gave (left empty, never guessed)."""
    writable_when: WriteGate | None = None
    on_write: list[WriteEffect] = Field(default_factory=list)
    motion: Motion | None = None
    """Writing it can make the drive move (see :class:`Motion`)."""
    live: Literal["process data", "volatile"] | None = None
    """Not a setting although writable: process data the master sends while the drive runs (a control word, a
    setpoint) or a value the device does not keep. A parameter set leaves it out, and says so."""

    @model_validator(mode="after")
    def _check_limits(self) -> Entry:
        if self.min is not None and self.max is not None and self.min > self.max:
            raise ValueError(Text(N_("{name}: min {min} is greater than max {max}"), name=self.name, min=self.min,
                                  max=self.max))
        if self.factor == 0:
            raise ValueError(Text(N_("{name}: factor must not be 0"), name=self.name))
        return self

    @property
    def decimals(self) -> int:
        """Digits after the decimal point implied by the factor (100 -> 2)."""
        f, n = float(self.factor), 0
        while f >= 10 and n < 6:
            f /= 10
            n += 1
        return n


class ObjectEntry(Entry):
    """One CANopen object dictionary entry (index, subindex)."""

    index: HexInt
    subindex: int = Field(0, ge=0, le=255)
    object_name: str | None = None
    """Name of the record/array this sub-entry belongs to (``Identity object`` for 0x1018sub1)."""
    object_type: Literal["VAR", "ARRAY", "RECORD"] = "VAR"
    code: str | None = None
    """Vendor code that shows the same data (``C00381`` for 0x1017), for cross reference only."""
    default_expr: str | None = None
    """CiA 306 ``$NODEID`` formula for the default (``$NODEID+0x180``); ``default`` is then None."""
    parameter_value: Value | None = None
    """DCF ``ParameterValue`` (raw); a ``$NODEID`` formula stays a string."""
    denotation: str | None = None
    """DCF ``Denotation``: the name a system integrator gave this object."""
    obj_flags: int | None = None
    """CiA 306 ``ObjFlags`` (bit 0: do not read in configuration, bit 1: do not write)."""
    section_keys: dict[str, str] | None = None
    """Keys of the object's EDS section the model has no field for (``UploadFile``, ``DownloadFile``,
    ``StorageLocation``, vendor keys), in file order; an export writes them back."""
    object_keys: dict[str, str] | None = None
    """On the first entry of an ARRAY/RECORD: keys of the object's own section (``[1018]``) the model has no field
    for, in file order; an export writes them back there."""
    pdo_mapping_kind: Literal["default", "TPDO", "RPDO"] | None = None
    """A CiA 311 ``PDOmapping`` beyond ``optional``/``no`` (mapped by default, only into a TPDO or an RPDO); an XDD
    export writes it back (an EDS knows only ``PDOMapping=1``). Only on a ``pdo_mappable`` object."""
    domain_object: bool = False
    """The file gave ``ObjectType=0x2`` (DOMAIN): read as a VAR, written as 0x2 again."""
    data_type_code: int | None = None
    """The file's ``DataType`` where the model reads another type: a type CiA 301 has but the model does not
    (INTEGER40, UNSIGNED48, TIME_OF_DAY ..., read as DOMAIN) or one the file defines (a DEFTYPE); an export writes
    it back."""
    value_texts: dict[str, str] | None = None
    """The file's text of ``DefaultValue``/``LowLimit``/``HighLimit``/``ParameterValue`` where the import read it
    with a change (a text default of a number, a value wider than its type, limits of a DOMAIN, ``$NODEID`` limits,
    limits dropped as LowLimit > HighLimit, ``CompactSubObj=255`` as sub 0's default ...; each with a warning): an
    export writes that text back; an edit of the value drops it. ``ObjectType`` where the entry is read as a VAR
    but the file says otherwise (``0x09`` on a sub-object, an ARRAY without sub-objects): written back as such.
    ``ParameterName`` ``""`` where the file left it empty (the entry is named ``Sub-index N``); an edit of the name
    drops it."""
    xdd_properties: dict[str, str] | None = None
    """``property`` elements of the entry's CiA 311 parameter that DriveBench has no meaning for (a tool's own:
    CANopenNode's ``CO_storageGroup`` ...), in file order; an XDD export writes them back (an EDS has no place)."""
    object_xdd_properties: dict[str, str] | None = None
    """On the first entry of an ARRAY/RECORD: those of the object's own parameter."""
    xdd_unique_id: str | None = None
    """The ``uniqueID`` of the entry's CiA 311 parameter where an XDD named one other than DriveBench's export
    would (CANopenEditor's ``UID_SUB_100300``); an XDD export writes the parameter under it again."""
    object_xdd_unique_id: str | None = None
    """On the first entry of an ARRAY/RECORD: that of the object's own parameter."""
    object_list: Literal["MandatoryObjects", "OptionalObjects", "ManufacturerObjects"] | None = None
    """On the first entry of an object: the EDS object list the file names it in, where that is not the one of its
    index range (lely-core lists 0x2000.. as optional objects, the HEIG-VD canopen-stack 0x1017 as mandatory); an
    export lists it there again."""
    object_flags: int | None = None
    """On each entry of an ARRAY/RECORD: the ``ObjFlags`` of the object's own section (``[1018]``), written back
    there; ``obj_flags`` is what holds for the entry (its own section's, else the object's)."""
    compact: bool = False
    """Read from a CiA 306 ``CompactSubObj`` array (one section, ``[xxxxName]``/``[xxxxValue]``); an EDS export
    writes it compact again while its entries still fit that form."""


class Parameter(Entry):
    """One vendor parameter: a Lenze code/subcode or a Siemens P/r parameter (and index after the point)."""

    code: str
    """Vendor name without subcode: ``C00088``, ``C0011``, ``P2040``, ``r2054``."""
    subcode: int = Field(0, ge=0, le=255)
    subcode_name: str | None = None
    index: HexInt | None = None
    """Explicit CANopen index where the family's addressing rule does not apply."""
    subindex: int | None = None
    parameter_sets: int = Field(1, ge=1, le=4)
    """How many Lenze parameter sets this code exists in (8200 vector: up to 4)."""

    @property
    def ref(self) -> str:
        """The name a user types: ``C00088``, ``C00118/3``, ``r2054.3``."""
        if self.subcode == 0:
            return self.code
        sep = "." if self.code[:1] in ("P", "r") else "/"
        return f"{self.code}{sep}{self.subcode}"


class CodeAddressing(BaseModel):
    """Lenze: index = 0x5FFF - (code + set_offset * (parameter set - 1)), subindex = subcode."""

    prefix: ClassVar[str] = "C"
    """How a code is written (``C00088``)."""
    point_is_subindex: ClassVar[bool] = False
    kind: Literal["lenze_code"] = "lenze_code"
    base: HexInt = 0x5FFF
    lowest_index: HexInt = 0x2000
    """Lowest index a code reaches (EMF2178IB §10.1: Lenze code indices lie between 0x40C0 and 0x5FFF)."""
    set_offset: int = 2000
    code_digits: int = 5
    """How the manual prints codes: 5 for ``C00088`` (8400), 4 for ``C0088`` (8200 vector/93XX)."""


class ParameterNumberAddressing(BaseModel):
    """MICROMASTER: index = 0x2000 + parameter number, subindex = the index after the point."""

    prefix: ClassVar[str] = "P"
    """How a parameter is written where the profile does not list it (``P2041``)."""
    point_is_subindex: ClassVar[bool] = True
    """A parameter the profile lists as ``.0`` has its index n after the point at sub-index n."""
    kind: Literal["siemens_mm4"] = "siemens_mm4"
    base: HexInt = 0x2000
    not_parameters: list[HexInt] = Field(default_factory=lambda: [0x2802, 0x2803])
    """Indices in the parameter range that are objects of their own, not parameters on the parameter channel
    (MICROMASTER CANopen option manual, object index rule: parameter channel 0x2000...0x2801 and 0x2804...0x5FFF;
    0x2802/0x2803 are the free process-data objects, not r2050/P2051)."""


class CanopenOnlyAddressing(BaseModel):
    prefix: ClassVar[str] = "C"
    point_is_subindex: ClassVar[bool] = False
    kind: Literal["canopen"] = "canopen"


Addressing = Annotated[
    CodeAddressing | ParameterNumberAddressing | CanopenOnlyAddressing, Field(discriminator="kind")
]


class Identity(BaseModel):
    model_config = ConfigDict(extra="forbid")

    vendor_name: str
    vendor_id: HexInt | None = None
    product_name: str
    product_code: HexInt | None = None
    revision: HexInt | None = None
    order_codes: list[str] = Field(default_factory=list)
    device_type: HexInt | None = None
    """Value of object 0x1000."""


class Features(BaseModel):
    """Communication capabilities the manual states."""

    model_config = ConfigDict(extra="forbid")

    sdo_channels: int = 1
    segmented_sdo: bool = True
    block_sdo: bool = False
    rpdo_count: int = 0
    tpdo_count: int = 0
    max_mapping_entries: int = 8
    sdo_word_tasks: bool = False
    """The SDO server recodes writes into word / double-word parameter tasks (MICROMASTER §3.2.4): 1 or 2 bytes are
    a word, 4 a double word; only a mixture of word and double word is refused (0x06070010), a word task to a byte
    object or a byte to a word object is taken. False: CiA 301 (the length must match, else 0x06070012/13)."""
    mapping_needs_invalid_pdo: bool = True
    """CiA 301: a mapping changes only while the PDO's COB-ID is invalid (bit 31). False where the manual changes
    it on a valid PDO (MICROMASTER: sub 0 := 0, entries, sub 0 := count)."""
    heartbeat_producer: bool = True
    heartbeat_consumers: int = 0
    node_guarding: bool = False
    node_id_range: tuple[int, int] = (1, 127)
    baud_rates_kbit: list[int] = Field(default_factory=lambda: [10, 20, 50, 125, 250, 500, 800, 1000])
    transport: Literal["canopen", "ethercat_coe"] = "canopen"
    sdo_processing_time_ms: Number | None = None
    """Typical parameter data processing time the manual gives (simulator default latency)."""


class EmcyCode(BaseModel):
    """A vendor meaning for an emergency code (and/or manufacturer-specific error number)."""

    model_config = ConfigDict(extra="forbid")

    code: HexInt
    text: str
    vendor_error: str | None = None
    """The device's own error number or name (8400: Lenze error number; MICROMASTER: F0070 ...)."""
    remedy: str | None = None


class SoftwareLimits(BaseModel):
    """Who keeps a CiA 402 drive inside its software position limits 0x607D. CiA 402 lets a drive that supports them
    clamp there (it stops at the limit and sets 0x6041 bit 11 *internal limit active*), but a drive in a velocity
    or torque mode need not: then the tool watches the position while it jogs or moves the drive and halts it."""

    model_config = ConfigDict(extra="forbid")

    drive_clamps: bool = False
    """The manual says the drive stops at 0x607D in every mode and sets 0x6041 bit 11."""
    clamps_ref: str | None = None
    """An object that switches the drive's own clamping: it clamps while this reads non-zero."""


class Profile(BaseModel):
    """A complete device profile (one JSON file in ``device_profiles/``)."""

    model_config = ConfigDict(extra="forbid")

    id: str = Field(pattern=r"^[a-z0-9][a-z0-9_.-]*$")
    version: str = "1"
    family: str = Field(pattern=r"^[a-z0-9][a-z0-9_.-]*$", max_length=64)
    """Profile family, the one family key (``lenze-8400``, ``lenze-emf2178ib``, ``siemens-mm4``, ``cia402``): a name
    for people and file lists; behaviour comes from the sections, never from this key."""
    identity: Identity
    source: str | None = None
    """The manual this profile was built from (title, edition, chapter)."""
    addressing: Addressing = Field(default_factory=CanopenOnlyAddressing)
    features: Features = Field(default_factory=Features)
    groups: list[str] = Field(default_factory=list)
    """Parameter groups in the manual's order."""
    objects: list[ObjectEntry] = Field(default_factory=list)
    parameters: list[Parameter] = Field(default_factory=list)
    emcy_codes: list[EmcyCode] = Field(default_factory=list)
    notes: list[str] = Field(default_factory=list)
    """Manual errata and ambiguities, with the reading this profile follows."""
    commands: CommandsSection | None = None
    """Save / restore defaults where they are not CiA 301's 0x1010/0x1011 (``device/profiles/commands.py``)."""
    sdo_channels: list[SdoServerChannel] = Field(default_factory=list)
    """Additional SDO servers the tool may switch on to read faster (``device/profiles/sdo_channels.py``)."""
    faults: FaultsSection | None = None
    """The drive's own fault numbers in words, where EMCY carries them, the fault parameters and the command source
    (``device/drive/faults.py``)."""
    abort_texts: AbortTexts | None = None
    """The manual's wording of SDO abort codes (``device/profiles/abort_texts.py``); CiA 301's where it has none."""
    pdo_rules: PdoRules | None = None
    """What the manual says about the PDOs beyond CiA 301 (``device/profiles/pdo_rules.py``)."""
    switches: SwitchesSection | None = None
    """DIP switches, node address / baud rate parameters and COB-ID base rules (``device/calculators/switches.py``): the
    DIP-switch calculator and the network planner list every profile that has one."""
    control: ControlSection | None = None
    """How the drive is switched, set and watched (``device/drive/control.py``); None: CiA 402 by its objects or
    none."""
    software_limits: SoftwareLimits = Field(default_factory=SoftwareLimits)
    """Whether the drive itself stops at 0x607D (default: no, the tool watches; ``services/control/soft_limits.py``)."""
    ethercat: EthercatSection | None = None
    """EtherCAT devices: the states of the slave's state machine (``device/profiles/ethercat_section.py``)."""
    commissioning: list[Sequence] = Field(default_factory=list)
    """The manuals' guided commissioning sequences as telegram data."""
    extra_sections: dict[str, dict[str, str]] = Field(default_factory=dict)
    """EDS sections (and FileInfo/DeviceInfo keys) the model has no field for, kept for round trips."""

    @model_validator(mode="after")
    def _check_unique(self) -> Profile:
        seen: set[tuple[int, int]] = set()
        for obj in self.objects:
            key = (obj.index, obj.subindex)
            if key in seen:
                raise ValueError(Text(N_("duplicate object 0x{index:04X}sub{subindex}"), index=obj.index,
                                      subindex=obj.subindex))
            seen.add(key)
        refs: set[tuple[str, int]] = set()
        for par in self.parameters:
            pkey = (par.code.upper(), par.subcode)
            if pkey in refs:
                raise ValueError(Text(N_("duplicate parameter {ref}"), ref=par.ref))
            refs.add(pkey)
        return self
