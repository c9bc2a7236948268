"""CiA 311 XDD/XDC import (ISO 15745 XML device descriptions) -> a :class:`Profile` with warnings.

The XML is parsed safely: a document with a DOCTYPE or ENTITY declaration is refused before parsing (no XXE, no
billion laughs), and lxml runs with entity resolution, DTD loading and network access off and without
``huge_tree`` (libxml2's depth and size limits stay on). No CiA 311 schema ships in a package, so the structure is
checked here, with line numbers.

The communication body (``ProfileBody_CommunicationNetwork_CANopen``) is turned into the sections an EDS holds
(``CANopenObject`` -> ``[xxxx]``, ``CANopenSubObject`` -> ``[xxxxsubN]``, ``actualValue`` -> ``ParameterValue``,
``deviceCommissioning`` -> ``[DeviceComissioning]``) and read by the EDS reader, so both formats get the same
readings and warnings. The device body (``ProfileBody_Device_CANopen``) gives the identity and, through an
object's ``uniqueIDRef``, the parameter (and its ``templateIDRef`` template) for what the object leaves out: name,
default, actual value, limits, description, denotation, the ``Unit``/``Factor`` properties DriveBench's export writes
and its ``EDS:`` properties (EDS keys without a CiA 311 attribute); an object without ``dataType``/``accessType``
takes them from the parameter's IEC type and ``access``. A ``dataTypeList`` code outside CiA 301's basic types
that it defines as one is read as that type; the first ProfileHeader's revision and source are the profile's.
The file attributes, NMT/LSS features, version elements, ``dummyUsage`` and ``productText`` become the EDS keys
:mod:`drivebench.device.formats.xdd_places` names, and ``PDOmapping`` ``TPDO``/``RPDO``/``default`` the object's
``pdo_mapping_kind``.
"""

from __future__ import annotations

import re

from lxml import etree

from drivebench.device.formats.eds import (
    BAUD_RATES_KBIT,
    DEVICE_INFO_DEFAULTS,
    MAX_EDS_BYTES,
    OBJECT_LISTS,
    OWN_SECTION,
    ImportedEds,
    Key,
    Section,
    range_object_list,
    read_sections,
)
from drivebench.device.formats.eds_quirks import Warnings
from drivebench.device.formats.wide_text import decode_wide
from drivebench.device.formats.xdd_places import (
    BODY_ATTRIBUTES,
    COMMISSIONING,
    DEVICE_FUNCTION,
    FILE_INFO,
    FILE_PARAMETER,
    GENERAL_FEATURES,
    MASTER_FEATURES,
    NUMBER_FEATURES,
    XDD_SECTION,
    eds_feature_value,
    eds_file_value,
)
from drivebench.device.profiles.profile import Profile
from drivebench.errors import ProfileError
from drivebench.i18n import N_, Text
from drivebench.protocol.datatypes import DATA_TYPE_BY_CODE, DataType

XML_SUFFIXES = (".xdd", ".xdc")
EDS_KEY_PREFIX = "EDS:"
"""A parameter ``property`` named ``EDS:UploadFile`` carries an EDS key CiA 311 has no attribute for."""
_DECLARATION = re.compile(r"<!\s*(DOCTYPE|ENTITY)", re.IGNORECASE)
_BAUD = re.compile(r"^\s*(\d+)\s*([KM])bps\s*$", re.IGNORECASE)
_OBJECT_KEYS = {"name": "ParameterName", "objectType": "ObjectType", "dataType": "DataType",
                "lowLimit": "LowLimit", "highLimit": "HighLimit", "accessType": "AccessType",
                "defaultValue": "DefaultValue", "actualValue": "ParameterValue", "denotation": "Denotation",
                "PDOmapping": "PDOMapping", "objFlags": "ObjFlags", "subNumber": "SubNumber"}
_PARAMETER_ACCESS = {"const": "const", "read": "ro", "write": "wo", "readWrite": "rw", "readWriteInput": "rwr",
                     "readWriteOutput": "rww"}
"""A CiA 311 parameter's ``access`` as the EDS AccessType (``noAccess`` has none)."""
_IEC_TYPES = {"BOOL": DataType.BOOLEAN, "SINT": DataType.INTEGER8, "CHAR": DataType.INTEGER8,
              "INT": DataType.INTEGER16, "DINT": DataType.INTEGER32, "LINT": DataType.INTEGER64,
              "USINT": DataType.UNSIGNED8, "BYTE": DataType.UNSIGNED8, "UINT": DataType.UNSIGNED16,
              "WORD": DataType.UNSIGNED16, "UDINT": DataType.UNSIGNED32, "DWORD": DataType.UNSIGNED32,
              "ULINT": DataType.UNSIGNED64, "LWORD": DataType.UNSIGNED64, "REAL": DataType.REAL32,
              "LREAL": DataType.REAL64, "STRING": DataType.VISIBLE_STRING, "WSTRING": DataType.UNICODE_STRING,
              "BITSTRING": DataType.OCTET_STRING}
"""A parameter's IEC 61131 type element as the CiA 301 type, for an object without ``dataType`` (generators such
as CANopenEditor type the parameter only)."""
_PDO_KINDS = {"default": "default", "tpdo": "TPDO", "rpdo": "RPDO"}
_EDS_PROPERTY = re.compile(r"^EDS:\[([^\]]+)\](.+)$")
OBJECT_LIST_PROPERTY = "EDS:[ObjectList]"
"""The property naming the EDS object list (``MandatoryObjects`` ...) an object was listed in off its index range
(no EDS key can be named ``[ObjectList]``)."""


def local(element: etree._Element) -> str:
    tag = element.tag
    return etree.QName(tag).localname if isinstance(tag, str) else ""


def parse_xml(data: bytes, source: str) -> etree._Element:
    """Bytes -> the root element, safely (see the module docstring). Raises ProfileError with the line."""
    if len(data) > MAX_EDS_BYTES:
        raise ProfileError(Text(N_("file is {count} bytes, more than the {limit} bytes a device description "
                                   "may have"), count=len(data), limit=MAX_EDS_BYTES), source=source)
    text = decode_wide(data)  # UTF-16/32: checked as text, not as bytes a byte pattern would miss
    if text is None:
        text = data.decode("latin-1")  # UTF-8 and the 8-bit encodings: the markup is ASCII either way
    declaration = _DECLARATION.search(text)
    if declaration is not None:
        line = text.count("\n", 0, declaration.start()) + 1
        raise ProfileError(Text(N_("a DOCTYPE or ENTITY declaration is not allowed in an XDD/XDC (it could read "
                                   "files or expand without end)")), source=source, line=line)
    parser = etree.XMLParser(resolve_entities=False, no_network=True, huge_tree=False, load_dtd=False,
                             dtd_validation=False, remove_pis=True)
    try:
        return etree.fromstring(data, parser)
    except etree.XMLSyntaxError as exc:
        raise ProfileError(Text(N_("not well-formed XML: {msg}"),
                                msg=exc.msg), source=source, line=exc.lineno or None) from exc


def one_line(element: etree._Element) -> str:
    """``element`` as XML on one line: the whitespace between elements left out (it holds no data), texts kept."""
    copy = etree.fromstring(etree.tostring(element))
    for node in copy.iter():
        if node.text is not None and not node.text.strip() and len(node):
            node.text = None
        if node.tail is not None and not node.tail.strip():
            node.tail = None
    return etree.tostring(copy, encoding="unicode").replace("\n", "&#10;").replace("\r", "&#13;")


def _body_type(body: etree._Element) -> str:
    for name, value in body.attrib.items():
        if etree.QName(name).localname == "type":
            return str(value).split(":")[-1]
    return ""


class _Builder:
    """EDS-shaped sections from the XML, with the source line of each key."""

    def __init__(self, source: str, notes: Warnings) -> None:
        self.source = source
        self.notes = notes
        self.sections: dict[str, Section] = {}
        self.listed: dict[str, int] = {}
        """How many objects each object list ([MandatoryObjects] ...) holds so far."""
        self.object_lists: dict[int, str] = {}
        """The EDS object list of an index where DriveBench's export names one (:data:`OBJECT_LIST_PROPERTY`)."""
        self.properties: dict[tuple[int, int], dict[str, str]] = {}
        """A tool's own parameter properties (``CO_storageGroup``) by (index, subindex); subindex -1: the object's."""
        self.pdo_kinds: dict[tuple[int, int], str] = {}
        """CiA 311 ``PDOmapping`` values beyond optional/no, by (index, subindex)."""
        self.unique_ids: dict[tuple[int, int], str] = {}
        """The parameter ``uniqueIDRef`` of each object (subindex -1 for an ARRAY/RECORD's own) and sub-object."""
        self.defined_types: dict[int, DataType] = {}
        """``dataTypeList`` codes outside CiA 301's basic types that name one (``<defType dataType="0040">
        <Unsigned32/>``)."""

    def header(self, profile_root: etree._Element) -> None:
        """ProfileRevision and ProfileSource (DriveBench's profile version and source) of the first header."""
        for child in next((e for e in profile_root if local(e) == "ProfileHeader"), []):
            text = (child.text or "").strip()
            key = {"ProfileRevision": "Version", "ProfileSource": "Source"}.get(local(child))
            if key is not None and text:
                self.put(OWN_SECTION, child.sourceline or 1, key, text)

    def file_info(self, body: etree._Element) -> None:
        """The ProfileBody file attributes as [FileInfo] keys (an empty one too: ``ModifiedBy=``)."""
        for attribute, key in FILE_INFO.items():
            value = body.get(attribute)
            if value is not None:
                self.put("FileInfo", body.sourceline or 1, key, eds_file_value(attribute, value))
        for attribute in BODY_ATTRIBUTES:
            if body.get(attribute) is not None:
                self.put(XDD_SECTION, body.sourceline or 1, attribute, str(body.get(attribute)))

    def eds_properties(self, parameter: etree._Element) -> None:
        """The ``EDS:[Section]Key`` properties DriveBench's export carries for EDS keys without a CiA 311 place; they
        are the EDS file's text, so they replace what an element gave (an ISO ``CreationDate``, ``ProductName=``)."""
        for child in parameter:
            found = _EDS_PROPERTY.match(str(child.get("name", ""))) if local(child) == "property" else None
            if found is not None and child.get("value") is not None:
                self.put(found.group(1), child.sourceline or 1, found.group(2), str(child.get("value")), replace=True)

    def features(self, element: etree._Element, attributes: dict[str, str]) -> None:
        """CANopenGeneralFeatures/CANopenMasterFeatures as [DeviceInfo] keys; an attribute left out is the schema's
        default (false, 0), not the EDS default (``SimpleBootUpSlave=1``); ``granularity`` has none."""
        for attribute, key in attributes.items():
            value = element.get(attribute)
            text = eds_feature_value(attribute, value) if value is not None else "0"
            if value is None and attribute in ("granularity", "NrOfNG_MonitoredNodes"):
                continue
            if text == "0" and key not in DEVICE_INFO_DEFAULTS and attribute not in NUMBER_FEATURES:
                continue  # false (the schema's default) of an attribute CiA 306 has no key for: the export writes it
            self.put("DeviceInfo", element.sourceline or 1, key, text)

    def data_types(self, body: etree._Element) -> None:
        layers = [e for e in body if local(e) == "ApplicationLayers"]
        for element in (e for layer in layers for e in layer):
            if local(element).lower() != "datatypelist":
                continue
            for definition in element:
                code_text, named = definition.get("dataType", ""), next(iter(definition), None)
                name = local(named).upper() if named is not None else ""
                try:
                    code = int(code_text, 16)
                except ValueError:
                    continue
                if code not in DATA_TYPE_BY_CODE and name in DataType.__members__:
                    self.defined_types[code] = DataType[name]

    def put(self, section: str, line: int, key: str, value: str, *, replace: bool = False) -> None:
        found = self.sections.get(section.upper())
        if found is None:
            found = self.sections[section.upper()] = Section(section, line)
        if replace or key.lower() not in found.keys:
            found.keys[key.lower()] = Key(key, value, line)

    def device(self, body: etree._Element) -> dict[str, etree._Element]:
        """Identity from the device body; returns parameters and templates by uniqueID."""
        identity = next((e for e in body.iter() if local(e) == "DeviceIdentity"), None)
        if identity is not None:
            self.versions([e for e in identity if local(e) == "version"])
            for child in identity:
                if local(child) == "productText":
                    self.comments(child)
                    continue
                key = {"vendorName": "VendorName", "vendorID": "VendorNumber", "productName": "ProductName",
                       "productID": "ProductNumber", "orderNumber": "OrderCode"}.get(local(child))
                text = (child.text or "").strip()
                if local(child) == "version" and re.fullmatch(r"0[xX][0-9a-fA-F]{1,8}", text):
                    key = "RevisionNumber"  # CiA 301 revision number as DriveBench writes it; "1.0" is no number
                if key == "OrderCode" and "ordercode" in (info := self.sections.get("DEVICEINFO", Section("", 0))).keys:
                    info.keys["ordercode"].value += f", {text}"  # one orderNumber element per code
                elif key is not None and (text or key in ("VendorName", "VendorNumber", "ProductNumber")):
                    self.put("DeviceInfo", child.sourceline or 1, key, text)  # an empty vendorID: VendorNumber=
        function = next((e for e in body if local(e) == DEVICE_FUNCTION), None)
        if function is not None:
            self.put(XDD_SECTION, function.sourceline or 1, DEVICE_FUNCTION, one_line(function))
        return {str(e.get("uniqueID")): e for e in body.iter()
                if local(e) in ("parameter", "parameterTemplate") and e.get("uniqueID")}

    def versions(self, elements: list[etree._Element]) -> None:
        """Each version element as it was (``Version_FW``, ``Version_HW``, a second FW ``Version_FW_2``), unless it
        is the one FW revision number DriveBench's export writes from ``RevisionNumber``."""
        texts = [(re.sub(r"[^A-Za-z]", "", str(e.get("versionType", ""))), (e.text or "").strip()) for e in elements]
        if len(texts) == 1 and texts[0][0] == "FW" and re.fullmatch(r"0x[0-9A-F]{8}", texts[0][1]):
            return
        seen: dict[str, int] = {}
        for element, (kind, text) in zip(elements, texts, strict=True):
            seen[kind] = seen.get(kind, 0) + 1
            suffix = f"_{seen[kind]}" if seen[kind] > 1 else ""
            self.put("DeviceInfo", element.sourceline or 1, f"Version_{kind}{suffix}", text)

    def comments(self, text: etree._Element) -> None:
        """A productText description as [Comments] lines (DriveBench writes Profile.notes there)."""
        description = next((e for e in text if local(e) == "description"), None)
        if description is None or description.text is None:
            return
        lines = description.text.split("\n")
        line = description.sourceline or 1
        self.put("Comments", line, "Lines", str(len(lines)))
        for number, note in enumerate(lines, start=1):
            self.put("Comments", line, f"Line{number}", note)

    def communication(self, body: etree._Element, parameters: dict[str, etree._Element]) -> None:
        for element in body.iter():
            name = local(element)
            line = element.sourceline or 1
            if name == "CANopenObject":
                self.object(element, parameters)
            elif name == "supportedBaudRate":
                rate = self.baud(element.get("value", ""), line)
                if rate in BAUD_RATES_KBIT:
                    self.put("DeviceInfo", line, f"BaudRate_{rate}", "1")
            elif name == "CANopenGeneralFeatures":
                for attribute, key in (("nrOfRxPDO", "NrOfRXPDO"), ("nrOfTxPDO", "NrOfTXPDO")):
                    if element.get(attribute) is not None:
                        self.put("DeviceInfo", line, key, str(element.get(attribute)))
                self.features(element, GENERAL_FEATURES)
            elif name == "CANopenMasterFeatures":
                self.features(element, MASTER_FEATURES)
            elif name == "dummy" and "=" in element.get("entry", ""):
                key, _, value = str(element.get("entry")).partition("=")
                self.put("DummyUsage", line, key.strip(), value.strip())
            elif name == "deviceCommissioning":
                for attribute, key in COMMISSIONING.items():
                    value = element.get(attribute)
                    if value is not None:
                        rate = self.baud(value, line) if attribute == "actualBaudRate" else None
                        self.put("DeviceComissioning", line, key, str(rate) if rate else value)

    def baud(self, text: str, line: int) -> int | None:
        found = _BAUD.match(text)
        if found is None:
            self.notes.add(line, "baudRate", Text(N_("{text!r} is not a bit rate like '250 Kbps': ignored"), text=text))
            return None
        return int(found.group(1)) * (1000 if found.group(2).upper() == "M" else 1)

    def object(self, element: etree._Element, parameters: dict[str, etree._Element]) -> None:
        line = element.sourceline or 1
        index_text = element.get("index", "")
        try:
            index = int(index_text, 16)
        except ValueError:
            self.notes.add(line, "index", Text(N_("CANopenObject index={value!r} is not 4 hex digits: skipped"),
                                               value=index_text))
            return
        section = f"{index:04X}"
        if section.upper() in self.sections:
            self.notes.add(line, "index", Text(N_("object 0x{index:04X} is in the object list twice: the first is "
                                                  "read"), index=index))
            return
        self.keys(section, element, parameters)
        subs = [e for e in element if local(e) == "CANopenSubObject"]
        if subs and element.get("subNumber") is None:
            self.put(section, line, "SubNumber", str(len(subs)))
        for sub in subs:
            sub_text = sub.get("subIndex", "")
            try:
                number = int(sub_text, 16)
            except ValueError:
                self.notes.add(sub.sourceline, "subIndex", Text(N_("CANopenSubObject subIndex={value!r} of "
                                                                   "0x{index:04X} is not hex: skipped"),
                                                                value=sub_text, index=index))
                continue
            self.keys(f"{section}sub{number:X}", sub, parameters)
        listing = self.object_lists.get(index, range_object_list(index))
        self.listed[listing] = self.listed.get(listing, 0) + 1
        self.put(listing, line, str(self.listed[listing]), f"0x{index:04X}")

    def keys(self, section: str, element: etree._Element, parameters: dict[str, etree._Element]) -> None:
        line = element.sourceline or 1
        target = self.sections.setdefault(section.upper(), Section(section, line)).keys
        for attribute, value in element.items():  # one pass over what the element has (a 5 MB XDD: 150,000)
            key = _OBJECT_KEYS.get(str(attribute))
            if key is None:
                continue
            if attribute == "dataType":
                value = self.data_type(value, line)
            elif attribute == "PDOmapping":
                kind = _PDO_KINDS.get(value.strip().lower())
                if kind is not None:
                    index, _, sub = section.upper().partition("SUB")
                    self.pdo_kinds[(int(index, 16), int(sub or "0", 16))] = kind
                value = "0" if value.strip().lower() == "no" else "1"
            target.setdefault(key.lower(), Key(key, value, line))
        reference = element.get("uniqueIDRef")
        if reference is None:
            return
        parameter = parameters.get(reference)
        if parameter is None:
            self.notes.add(line, "uniqueIDRef", Text(N_("uniqueIDRef={reference!r} names no parameter of the device "
                                                        "profile: ignored"), reference=reference))
            return
        template = parameters.get(str(parameter.get("templateIDRef"))) if parameter.get("templateIDRef") else None
        holds_value = local(element) == "CANopenSubObject" or not any(local(e) == "CANopenSubObject"
                                                                       for e in element)
        index, _, sub = section.upper().partition("SUB")
        self.unique_ids[(int(index, 16), int(sub, 16) if sub else (0 if holds_value else -1))] = reference
        for source in (parameter, template):
            if source is not None:
                self.from_parameter(section, source, holds_value=holds_value)

    def data_type(self, text: str, line: int) -> str:
        """A dataType attribute as an EDS DataType: hex, and a code the dataTypeList defines as its basic type."""
        value = f"0x{text}" if not text.lower().startswith("0x") else text
        try:
            defined = self.defined_types.get(int(value, 16))
        except ValueError:
            return value
        if defined is None:
            return value
        self.notes.add(line, "dataType", Text(N_("dataType={text} is defined in the dataTypeList: read as {value}"),
                                              text=text, value=defined.value))
        return f"0x{defined.code:04X}"

    def from_parameter(self, section: str, parameter: etree._Element, *, holds_value: bool) -> None:
        """What the object leaves out, from its parameter (``put`` keeps what is already there); the access and the
        type only for an object holding a value (not the head of an ARRAY/RECORD)."""
        line = parameter.sourceline or 1
        access = _PARAMETER_ACCESS.get(str(parameter.get("access")))
        if holds_value and access is not None:
            self.put(section, line, "AccessType", access)
        for child in parameter:
            name = local(child)
            if holds_value and name in _IEC_TYPES:
                data_type = _IEC_TYPES[name]
                if name == "BITSTRING" and not any(local(e) == "defaultValue" for e in parameter):
                    data_type = DataType.DOMAIN  # bytes without a default: CANopenEditor writes DOMAIN so
                self.put(section, child.sourceline or line, "DataType", f"0x{data_type.code:04X}")
            elif name == "denotation":
                text = " ".join(t.strip() for t in child.itertext() if t.strip())
                if text:
                    self.put(section, child.sourceline or line, "Denotation", text)
            elif name == "label" and (child.text or "").strip():
                self.put(section, line, "ParameterName", (child.text or "").strip())
            elif name == "description":  # an empty one too: the EDS's ``Description=`` it was written from
                self.put(section, child.sourceline or line, "Description", (child.text or "").strip())
            elif name in ("defaultValue", "actualValue") and child.get("value") is not None:
                key = "DefaultValue" if name == "defaultValue" else "ParameterValue"
                self.put(section, child.sourceline or line, key, str(child.get("value")))
            elif name == "property" and child.get("value") is not None:
                key = str(child.get("name"))
                if key == OBJECT_LIST_PROPERTY and str(child.get("value")) in OBJECT_LISTS:
                    self.object_lists[int(section[:4], 16)] = str(child.get("value"))
                elif key in ("Unit", "Factor") or key.startswith(EDS_KEY_PREFIX):
                    self.put(section, child.sourceline or line, key.removeprefix(EDS_KEY_PREFIX),
                             str(child.get("value")))
                else:  # a tool's own: kept for an XDD written again
                    index, _, sub = section.upper().partition("SUB")
                    address = (int(index, 16), int(sub, 16) if sub else (0 if holds_value else -1))
                    self.properties.setdefault(address, {}).setdefault(key, str(child.get("value")))
            elif name == "allowedValues":
                for bound in child.iter():
                    limit = {"minValue": "LowLimit", "maxValue": "HighLimit"}.get(local(bound))
                    if limit is not None and bound.get("value") is not None:
                        self.put(section, bound.sourceline or line, limit, str(bound.get("value")))


def read_xdd(data: bytes, *, source: str) -> ImportedEds:
    """Read an XDD or XDC into a Profile and the warnings of the readings applied. Raises ProfileError (with the
    line) for unsafe or malformed XML and for a file without a CANopen object list."""
    root = parse_xml(data, source)
    if local(root) not in ("ISO15745ProfileContainer", "ISO15745Profile"):
        raise ProfileError(Text(N_("not a CiA 311 device description: the root element is <{element}>, not "
                                   "<ISO15745ProfileContainer>"),
                                element=local(root)), source=source, line=root.sourceline)
    bodies = [e for e in root.iter() if local(e) == "ProfileBody"]
    communication = [b for b in bodies if _body_type(b).startswith("ProfileBody_CommunicationNetwork_CANopen")]
    if not communication or not any(local(e) == "CANopenObjectList" for e in communication[0].iter()):
        raise ProfileError(Text(N_("no object dictionary: no ProfileBody_CommunicationNetwork_CANopen with a "
                                   "CANopenObjectList")), source=source, line=root.sourceline)
    notes = Warnings(source)
    builder = _Builder(source, notes)
    parameters: dict[str, etree._Element] = {}
    profiles = [root] if local(root) == "ISO15745Profile" else [e for e in root if local(e) == "ISO15745Profile"]
    if profiles:
        builder.header(profiles[0])
    builder.data_types(communication[0])
    for body in [communication[0], *(b for b in bodies if b is not communication[0])]:
        builder.file_info(body)  # the communication body's first; one the device body alone has too
    for body in bodies:
        if _body_type(body).startswith("ProfileBody_Device_CANopen"):
            parameters |= builder.device(body)
    if FILE_PARAMETER in parameters:
        builder.eds_properties(parameters[FILE_PARAMETER])
    if "DEVICEINFO" not in builder.sections:
        builder.put("DeviceInfo", root.sourceline or 1, "VendorName", "")
        notes.add(root.sourceline, "DeviceIdentity", Text(N_("no ProfileBody_Device_CANopen with a DeviceIdentity: "
                                                             "vendor and product are left unknown")))
    builder.communication(communication[0], parameters)
    for listing in OBJECT_LISTS:
        found = builder.sections.get(listing.upper())
        if found is not None:
            found.keys["supportedobjects"] = Key("SupportedObjects", str(builder.listed[listing]), found.line)
    imported = read_sections(builder.sections, source, notes)
    profile = with_properties(with_pdo_kinds(imported.profile, builder.pdo_kinds), builder.properties)
    profile = with_unique_ids(profile, builder.unique_ids)
    return ImportedEds(profile, imported.warnings)


def with_pdo_kinds(profile: Profile, kinds: dict[tuple[int, int], str]) -> Profile:
    """``profile`` with each mappable object's CiA 311 PDOmapping kind (``TPDO``, ``RPDO``, ``default``)."""
    if not kinds:
        return profile
    objects = [o.model_copy(update={"pdo_mapping_kind": kinds[(o.index, o.subindex)]})
               if o.pdo_mappable and (o.index, o.subindex) in kinds else o for o in profile.objects]
    return profile.model_copy(update={"objects": objects})


def with_properties(profile: Profile, properties: dict[tuple[int, int], dict[str, str]]) -> Profile:
    """``profile`` with each entry's (and each ARRAY/RECORD's, on its first entry) own tool properties."""
    if not properties:
        return profile
    objects, seen = [], set()
    for entry in profile.objects:
        update: dict[str, dict[str, str]] = {}
        if (entry.index, entry.subindex) in properties:
            update["xdd_properties"] = properties[(entry.index, entry.subindex)]
        if entry.index not in seen and (entry.index, -1) in properties:
            update["object_xdd_properties"] = properties[(entry.index, -1)]
        seen.add(entry.index)
        objects.append(entry.model_copy(update=update) if update else entry)
    return profile.model_copy(update={"objects": objects})


def with_unique_ids(profile: Profile, unique_ids: dict[tuple[int, int], str]) -> Profile:
    """``profile`` with each entry's (and each ARRAY/RECORD's, on its first entry) parameter uniqueID, where it is
    not the one DriveBench's export gives (``UID_OBJ_200001``, ``UID_OBJ_2000``): that one needs no keeping."""
    objects, seen = [], set()
    for entry in profile.objects:
        update: dict[str, str] = {}
        own = unique_ids.get((entry.index, entry.subindex))
        if own is not None and own != f"UID_OBJ_{entry.index:04X}{entry.subindex:02X}":
            update["xdd_unique_id"] = own
        whole = unique_ids.get((entry.index, -1))
        if entry.index not in seen and whole is not None and whole != f"UID_OBJ_{entry.index:04X}":
            update["object_xdd_unique_id"] = whole
        seen.add(entry.index)
        objects.append(entry.model_copy(update=update) if update else entry)
    return profile.model_copy(update={"objects": objects}) if unique_ids else profile
