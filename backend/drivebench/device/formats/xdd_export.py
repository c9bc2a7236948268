"""CiA 311 export: a :class:`Profile` -> XDD, or a node's configured values -> XDC, that :func:`read_xdd` reads
back to the same objects and identity.

Two ISO 15745 profiles in one container: ``ProfileBody_Device_CANopen`` (DeviceIdentity, and a parameter per object
carrying what CANopenObject attributes cannot: description, ``Unit`` and ``Factor`` properties) and
``ProfileBody_CommunicationNetwork_CANopen`` (CANopenObjectList, bit rates, general features; in an XDC the
``actualValue`` of each configured object and ``deviceCommissioning``). Values are raw, as in an EDS.
"""

from __future__ import annotations

from collections.abc import Mapping
from datetime import UTC, datetime

from lxml import etree

from drivebench.device.formats.eds import DEVICE_INFO_DEFAULTS, file_info_defaults, parse_int
from drivebench.device.formats.eds_export import (
    Address,
    export_value_text,
    node_value,
    object_type_text,
    objects_by_index,
    written_name,
)
from drivebench.device.formats.xdd import EDS_KEY_PREFIX, OBJECT_LIST_PROPERTY
from drivebench.device.formats.xdd_places import (
    BODY_ATTRIBUTES,
    COMMISSIONING,
    DEVICE_FUNCTION,
    FILE_INFO,
    FILE_PARAMETER,
    GENERAL_FEATURES,
    MASTER_FEATURES,
    VERSION_KEY,
    XDD_SECTION,
    extra,
    unplaced,
    xdd_feature_value,
    xdd_file_value,
)
from drivebench.device.profiles.profile import ObjectEntry, Profile, Value
from drivebench.protocol.datatypes import DataType

NS = "http://www.canopen.org/xml/1.0"
XSI = "http://www.w3.org/2001/XMLSchema-instance"
OBJECT_TYPE_NUMBERS = {"VAR": "7", "ARRAY": "8", "RECORD": "9"}
IEC_TYPES = {DataType.BOOLEAN: "BOOL", DataType.INTEGER8: "SINT", DataType.INTEGER16: "INT", DataType.INTEGER32: "DINT",
             DataType.INTEGER64: "LINT", DataType.UNSIGNED8: "USINT", DataType.UNSIGNED16: "UINT",
             DataType.UNSIGNED32: "UDINT", DataType.UNSIGNED64: "ULINT", DataType.REAL32: "REAL",
             DataType.REAL64: "LREAL", DataType.VISIBLE_STRING: "STRING", DataType.UNICODE_STRING: "WSTRING",
             DataType.OCTET_STRING: "BITSTRING", DataType.DOMAIN: "BITSTRING"}
"""The IEC 61131 type of a parameter holding an object's value (CiA 311 parameters are typed so); BYTE else."""


def type_element_name(data_type: DataType) -> str:
    """The element naming a CiA 301 type in a ``dataTypeList`` ``defType``: ``Unsigned32``, ``Visible_String``."""
    return "_".join(part.capitalize() for part in data_type.value.split("_"))


def export_type_code(entry: ObjectEntry) -> int:
    """The CiA 301 code for ``dataType``: the file's own where the model reads the type as DOMAIN (INTEGER40,
    TIME_OF_DAY ...), which an XDD holds as well; a DEFTYPE the model reads as its basic type is written as that."""
    if entry.data_type_code is not None and entry.data_type is DataType.DOMAIN:
        return entry.data_type_code
    return entry.data_type.code


def _el(parent: etree._Element | None, local_name: str, text: str | None = None, /, **attributes: str
        ) -> etree._Element:
    tag = f"{{{NS}}}{local_name}"
    element = etree.Element(tag, nsmap={None: NS, "xsi": XSI}) if parent is None else etree.SubElement(parent, tag)
    for key, value in attributes.items():
        element.set(key, value)
    if text is not None:
        element.text = text
    return element


def _header(profile_root: etree._Element, profile: Profile, name: str, classification: str) -> None:
    header = _el(profile_root, "ProfileHeader")
    _el(header, "ProfileIdentification", f"CANopen {name}")
    _el(header, "ProfileRevision", profile.version)
    _el(header, "ProfileName", profile.identity.product_name)
    _el(header, "ProfileSource", profile.source or "")
    _el(header, "ProfileClassID", classification)
    _el(header, "ISO15745Reference").extend([
        _child("ISO15745Part", "1"), _child("ISO15745Edition", "1"), _child("ProfileTechnology", "CANopen")])


def _child(name: str, text: str) -> etree._Element:
    element = etree.Element(f"{{{NS}}}{name}")
    element.text = text
    return element


def _body(profile_root: etree._Element, kind: str, profile: Profile) -> etree._Element:
    """A ProfileBody with the file attributes of the profile's [FileInfo] (where it has none: the EDS export's
    defaults, DriveBench and now)."""
    now = datetime.now(UTC)
    file_info = extra(profile, "FileInfo")
    made = {"fileName": file_info_defaults(profile)["FileName"], "fileCreator": "DriveBench",
            "fileCreationDate": now.strftime("%Y-%m-%d"), "fileCreationTime": now.strftime("%H:%M:%S"),
            "fileVersion": "1"}
    if "CreationDate" in file_info and "CreationTime" not in file_info:
        del made["fileCreationTime"]
    for attribute, key in FILE_INFO.items():
        if key in file_info:
            made[attribute] = xdd_file_value(attribute, file_info[key])
    kept = extra(profile, XDD_SECTION)
    body = _el(profile_root, "ProfileBody", **{a: kept[a] for a in BODY_ATTRIBUTES[:2] if a in kept},
               **{a: made[a] for a in FILE_INFO if a in made}, **{a: kept[a] for a in BODY_ATTRIBUTES[2:] if a in kept})
    body.set(f"{{{XSI}}}type", kind)
    return body


def _features(management: etree._Element, profile: Profile) -> None:
    """CANopenGeneralFeatures and CANopenMasterFeatures from [DeviceInfo] (CiA 306 defaults where it has none)."""
    info = {**DEVICE_INFO_DEFAULTS, **extra(profile, "DeviceInfo")}
    general = _el(management, "CANopenGeneralFeatures")
    for element, names in ((general, GENERAL_FEATURES), (_el(management, "CANopenMasterFeatures"), MASTER_FEATURES)):
        for attribute, key in names.items():
            text = info.get(key, None if attribute == "NrOfNG_MonitoredNodes" else "0")  # else: the schema default
            if text is not None:
                element.set(attribute, xdd_feature_value(attribute, text))
    general.set("nrOfRxPDO", str(profile.features.rpdo_count))
    general.set("nrOfTxPDO", str(profile.features.tpdo_count))


def _versions(identity: etree._Element, profile: Profile) -> None:
    """The DeviceIdentity version elements as the file had them (``Version_FW`` ...), else the revision number."""
    kept = [(VERSION_KEY.match(k), v) for k, v in extra(profile, "DeviceInfo").items()]
    versions = [(found.group(1), value) for found, value in kept if found is not None]
    if not versions and profile.identity.revision is not None:
        versions = [("FW", f"0x{profile.identity.revision:08X}")]
    for kind, text in versions:
        _el(identity, "version", text, versionType=kind)


def _device_function(body: etree._Element, profile: Profile) -> None:
    """The DeviceFunction element an XDD came with (its characteristicsList ...), in this file's namespace."""
    text = extra(profile, XDD_SECTION).get(DEVICE_FUNCTION)
    if not text:
        return
    try:
        function = etree.fromstring(text, etree.XMLParser(resolve_entities=False, no_network=True))
    except etree.XMLSyntaxError:
        return  # edited into no XML: nothing to write
    source = etree.QName(function).namespace
    for element in function.iter(etree.Element):
        name = etree.QName(element)
        if name.namespace == source:
            element.tag = f"{{{NS}}}{name.localname}"
    etree.cleanup_namespaces(function)
    body.append(function)


def _file_parameter(parameters: etree._Element, profile: Profile) -> None:
    """The EDS keys CiA 311 has no place for as ``EDS:[Section]Key`` properties, so an import gets them back."""
    keys = unplaced(profile)
    if not keys:
        return
    parameter = _el(parameters, "parameter", uniqueID=FILE_PARAMETER, access="noAccess")
    _el(parameter, "label", "EDS keys without a CiA 311 place", lang="en")
    _el(parameter, "BYTE")
    for section, key, value in keys:
        _el(parameter, "property", None, name=f"{EDS_KEY_PREFIX}[{section}]{key}", value=value)


def export_warnings(profile: Profile) -> list[str]:
    """What the XDD export cannot say in CiA 311 terms: each EDS key without a place (``[DeviceInfo] CompactPDO``);
    the export keeps them as DriveBench ``EDS:`` properties that other tools skip."""
    return [f"[{section}] {key}" for section, key, _ in unplaced(profile)]


def _uid(entry: ObjectEntry) -> str:
    return entry.xdd_unique_id or f"UID_OBJ_{entry.index:04X}{entry.subindex:02X}"


def _has_parameter(entry: ObjectEntry) -> bool:
    """Whether a VAR needs a parameter for what CANopenObject has no attribute for."""
    return entry.description is not None or entry.unit is not None or entry.factor != 1 or bool(entry.section_keys) \
        or (entry.object_list is not None and entry.object_type == "VAR") or bool(entry.xdd_properties) \
        or entry.xdd_unique_id is not None


def _parameter(parameters: etree._Element, entry: ObjectEntry) -> None:
    if not _has_parameter(entry):
        return
    parameter = _el(parameters, "parameter", uniqueID=_uid(entry), access="read")
    _el(parameter, "label", entry.name, lang="en")
    if entry.description is not None:
        _el(parameter, "description", entry.description, lang="en")
    _el(parameter, IEC_TYPES.get(entry.data_type, "BYTE"))
    for name, value in (("Unit", entry.unit), ("Factor", None if entry.factor == 1 else str(entry.factor))):
        if value is not None:
            _el(parameter, "property", None, name=name, value=value)
    for key, value in (entry.section_keys or {}).items():  # EDS keys without a CiA 311 attribute
        _el(parameter, "property", None, name=f"{EDS_KEY_PREFIX}{key}", value=value)
    _object_list_property(parameter, entry)
    _tool_properties(parameter, entry.xdd_properties)


def _tool_properties(parameter: etree._Element, properties: dict[str, str] | None) -> None:
    for key, value in (properties or {}).items():  # a tool's own, as the uploaded XDD had them
        _el(parameter, "property", None, name=key, value=value)


def _object_list_property(parameter: etree._Element, entry: ObjectEntry) -> None:
    if entry.object_list is not None:  # an XDD has no object lists: where the EDS listed it off its index range
        _el(parameter, "property", None, name=OBJECT_LIST_PROPERTY, value=entry.object_list)


def _object_parameter(parameters: etree._Element, index: int, first: ObjectEntry) -> str:
    """A parameter carrying the keys of an ARRAY/RECORD's own EDS section (``object_keys``); its uniqueID."""
    unique_id = first.object_xdd_unique_id or f"UID_OBJ_{index:04X}"
    parameter = _el(parameters, "parameter", uniqueID=unique_id, access="read")
    _el(parameter, "label", first.object_name or first.name, lang="en")
    _el(parameter, "BYTE")
    for key, value in (first.object_keys or {}).items():
        if key != "SubNumber":  # in the subNumber attribute
            _el(parameter, "property", None, name=f"{EDS_KEY_PREFIX}{key}", value=value)
    _object_list_property(parameter, first)
    _tool_properties(parameter, first.object_xdd_properties)
    return unique_id


def sub_number(first: ObjectEntry, listed: int) -> int:
    """An ARRAY/RECORD's subNumber: the file's SubNumber where it differs from the sub-objects listed (a DCF
    listing some of them), else their count."""
    try:
        return int((first.object_keys or {}).get("SubNumber", str(listed)), 0)
    except ValueError:
        return listed


def xdd_object_type(entry: ObjectEntry) -> str:
    """``objectType`` of an entry's CANopenObject/CANopenSubObject (a number, CiA 311): the file's where the import
    read the entry as a VAR otherwise."""
    try:
        return str(parse_int(object_type_text(entry)))
    except ValueError:
        return "2" if entry.domain_object else "7"


def _object_attributes(element: etree._Element, entry: ObjectEntry, value: Value | None, *,
                       with_flags: bool) -> None:
    element.set("name", written_name(entry))
    element.set("objectType", xdd_object_type(entry))
    element.set("dataType", f"{export_type_code(entry):04X}")
    element.set("accessType", entry.access.value)
    texts = export_value_text(entry, value)
    for attribute, key in (("defaultValue", "DefaultValue"), ("lowLimit", "LowLimit"), ("highLimit", "HighLimit"),
                           ("actualValue", "ParameterValue"), ("denotation", "Denotation")):
        if key in texts:
            element.set(attribute, texts[key])
    element.set("PDOmapping", (entry.pdo_mapping_kind or "optional") if entry.pdo_mappable else "no")
    if with_flags and entry.obj_flags is not None:
        element.set("objFlags", f"{entry.obj_flags:X}")
    if _has_parameter(entry):
        element.set("uniqueIDRef", _uid(entry))


def export_xdd(profile: Profile, *, node_id: int | None = None, values: Mapping[Address, Value] | None = None,
               xdc: bool = False, baud_kbit: int | None = None) -> bytes:
    """``profile`` as a CiA 311 XDD, or with ``xdc=True`` an XDC whose ``actualValue`` are ``values`` (raw, by
    (index, subindex)) and whose ``deviceCommissioning`` names ``node_id``."""
    container = _el(None, "ISO15745ProfileContainer")
    device = _el(container, "ISO15745Profile")
    _header(device, profile, "device profile", "Device")
    device_body = _body(device, "ProfileBody_Device_CANopen", profile)
    identity = _el(device_body, "DeviceIdentity")
    ident = profile.identity
    info = {key.lower(): value for key, value in extra(profile, "DeviceInfo").items()}
    _el(identity, "vendorName", ident.vendor_name)
    if ident.vendor_id is not None or info.get("vendornumber") == "":
        _el(identity, "vendorID", "" if ident.vendor_id is None else f"0x{ident.vendor_id:08X}")
    _el(identity, "productName", ident.product_name)
    if ident.product_code is not None or info.get("productnumber") == "":
        _el(identity, "productID", "" if ident.product_code is None else f"0x{ident.product_code:08X}")
    if profile.notes:  # the EDS [Comments] lines
        _el(_el(identity, "productText"), "description", "\n".join(profile.notes), lang="en")
    for code in ident.order_codes:
        _el(identity, "orderNumber", code)
    _versions(identity, profile)
    _device_function(device_body, profile)
    parameters = _el(_el(device_body, "ApplicationProcess"), "parameterList")
    _file_parameter(parameters, profile)

    network = _el(container, "ISO15745Profile")
    _header(network, profile, "communication network profile", "CommunicationNetwork")
    network_body = _body(network, "ProfileBody_CommunicationNetwork_CANopen", profile)
    layers = _el(network_body, "ApplicationLayers")
    by_index = objects_by_index(profile)
    type_list = _el(layers, "dataTypeList")
    for data_type in sorted({e.data_type for es in by_index.values() for e in es}, key=lambda t: t.code):
        _el(_el(type_list, "defType", dataType=f"{data_type.code:04X}"), type_element_name(data_type))
    object_list = _el(layers, "CANopenObjectList")
    for index, entries in by_index.items():
        first = entries[0]
        obj = _el(object_list, "CANopenObject", index=f"{index:04X}")
        if len(entries) == 1 and first.subindex == 0 and first.object_type == "VAR":
            _object_attributes(obj, first, node_value(first, values or {}, node_id, xdc), with_flags=True)
            _parameter(parameters, first)
            continue
        flags = {e.obj_flags for e in entries}
        shared = flags.pop() if len(flags) == 1 else None
        kind = first.object_type if first.object_type != "VAR" else "RECORD"
        obj.set("name", first.object_name or first.name)
        obj.set("objectType", OBJECT_TYPE_NUMBERS[kind])
        obj.set("subNumber", str(sub_number(first, len(entries))))
        if shared is not None:
            obj.set("objFlags", f"{shared:X}")
        if set(first.object_keys or {}) - {"SubNumber"} or first.object_list is not None \
                or first.object_xdd_properties or first.object_xdd_unique_id:
            obj.set("uniqueIDRef", _object_parameter(parameters, index, first))
        for entry in entries:
            sub = _el(obj, "CANopenSubObject", subIndex=f"{entry.subindex:02X}")
            _object_attributes(sub, entry, node_value(entry, values or {}, node_id, xdc), with_flags=shared is None)
            _parameter(parameters, entry)
    dummies = extra(profile, "DummyUsage")
    if dummies:
        usage = _el(layers, "dummyUsage")
        for key, value in dummies.items():
            _el(usage, "dummy", entry=f"{key}={value}")
    transport = _el(_el(network_body, "TransportLayers"), "PhysicalLayer")
    baud = _el(transport, "baudRate", defaultValue=f"{(profile.features.baud_rates_kbit or [250])[-1]} Kbps")
    for rate in profile.features.baud_rates_kbit:
        _el(baud, "supportedBaudRate", value=f"{rate} Kbps")
    management = _el(network_body, "NetworkManagement")
    _features(management, profile)
    kept = extra(profile, "DeviceComissioning")
    if kept and not xdc:
        commissioning = _el(management, "deviceCommissioning")
        for attribute, key in COMMISSIONING.items():
            if key in kept:
                text = kept[key]
                commissioning.set(attribute, f"{text} Kbps" if key == "Baudrate" and text.isdigit() else text)
    if xdc:
        commissioning = _el(management, "deviceCommissioning", nodeID=str(node_id or 1),
                            nodeName=profile.identity.product_name, networkNumber="1", networkName="",
                            CANopenManager="false")
        if baud_kbit is not None:
            commissioning.set("actualBaudRate", f"{baud_kbit} Kbps")
    warnings = export_warnings(profile)
    if warnings:
        container.insert(0, etree.Comment(" EDS keys without a CiA 311 place, kept as EDS: properties of "
                                          f"{FILE_PARAMETER}: {', '.join(warnings)} ".replace("--", "- -")))
    return etree.tostring(container, xml_declaration=True, encoding="UTF-8", pretty_print=True)
