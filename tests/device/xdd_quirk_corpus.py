"""A corpus of small XDD and EDS files for what CiA 311 can say beyond the object list (written here, no vendor's
file copied): PDO direction, NMT/LSS features, file and version elements, and the EDS sections an XDD has a place
for (or none). :func:`xdd` builds an XDD from parts so the hypothesis round trips can vary each of them.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from xml.sax.saxutils import quoteattr

from tests.device.quirk_corpus import BASE

PDO_KINDS = ("TPDO", "RPDO", "default", "optional", "no")


def _attributes(values: Mapping[str, str]) -> str:
    return "".join(f" {name}={quoteattr(value)}" for name, value in values.items())


def xdd(*, pdo: Sequence[str] = PDO_KINDS, general: Mapping[str, str] | None = None,
        master: Mapping[str, str] | None = None, file: Mapping[str, str] | None = None,
        device_file: Mapping[str, str] | None = None,
        versions: Sequence[tuple[str, str]] = (("FW", "0x00010002"),)) -> bytes:
    """An XDD of a small I/O device: object 0x2000+n with ``PDOmapping=pdo[n]``, the features, the ProfileBody file
    attributes (``device_file``: the device body's where they differ) and DeviceIdentity versions given."""
    file_attributes = _attributes(file or {"fileName": "io.xdd", "fileCreator": "Hand", "fileCreationDate":
                                           "2024-03-03", "fileVersion": "1"})
    device_attributes = _attributes(device_file) if device_file is not None else file_attributes
    general_attributes = _attributes({"granularity": "8", **(general or {}), "nrOfRxPDO": "0", "nrOfTxPDO": "0"})
    version_elements = "".join(f'<version versionType="{kind}">{text}</version>' for kind, text in versions)
    objects = "".join(
        f'<CANopenObject index="{0x2000 + n:04X}" name="Value {n}" objectType="7" dataType="0006" accessType="rw" '
        f'defaultValue="0" PDOmapping="{kind}"/>' for n, kind in enumerate(pdo))
    header = ('<ProfileHeader><ProfileIdentification>x</ProfileIdentification><ProfileRevision>1</ProfileRevision>'
              '<ProfileName>x</ProfileName><ProfileSource/><ProfileClassID>{0}</ProfileClassID></ProfileHeader>')
    text = f"""<?xml version="1.0" encoding="UTF-8"?>
<ISO15745ProfileContainer xmlns="http://www.canopen.org/xml/1.0" xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance">
  <ISO15745Profile>
    {header.format("Device")}
    <ProfileBody xsi:type="ProfileBody_Device_CANopen"{device_attributes}>
      <DeviceIdentity>
        <vendorName>Example IO</vendorName><vendorID>0x000004D2</vendorID><productName>IO 16</productName>
        {version_elements}
      </DeviceIdentity>
    </ProfileBody>
  </ISO15745Profile>
  <ISO15745Profile>
    {header.format("CommunicationNetwork")}
    <ProfileBody xsi:type="ProfileBody_CommunicationNetwork_CANopen"{file_attributes}>
      <ApplicationLayers>
        <CANopenObjectList>
          <CANopenObject index="1000" name="Device type" objectType="7" dataType="0007" accessType="ro"
            defaultValue="0x00030191" PDOmapping="no"/>
          {objects}
        </CANopenObjectList>
      </ApplicationLayers>
      <NetworkManagement>
        <CANopenGeneralFeatures{general_attributes}/>
        <CANopenMasterFeatures{_attributes(master or {})}/>
      </NetworkManagement>
    </ProfileBody>
  </ISO15745Profile>
</ISO15745ProfileContainer>
"""
    return text.encode()


ALL_FEATURES = xdd(
    general={"groupMessaging": "true", "dynamicChannels": "3", "selfStartingDevice": "true",
             "SDORequestingDevice": "true", "granularity": "0", "bootUpSlave": "false",
             "layerSettingServiceSlave": "true", "ngSlave": "true", "ngMaster": "false", "NrOfNG_MonitoredNodes": "4"},
    master={"bootUpMaster": "true", "flyingMaster": "true", "SDOManager": "false", "configurationManager": "true",
            "layerSettingServiceMaster": "true"})
VERSIONED = xdd(
    file={"fileName": "io16.xdd", "fileCreator": "Vendor Tool 3.1", "fileCreationDate": "2021-06-30",
          "fileCreationTime": "13:37:21", "fileModificationDate": "2022-01-02", "fileModificationTime": "08:00:00",
          "fileModifiedBy": "J. Doe", "fileVersion": "1.02"},
    versions=(("FW", "1.2.3"), ("HW", "B"), ("SW", "0x00010002"), ("FW", "boot 0.9")))


def _section(text: str, name: str, body: str) -> str:
    start = text.index(f"[{name}]\n")
    end = text.index("\n\n", start)
    return text[:start] + f"[{name}]\n{body}" + text[end:]


EDS_SECTIONS = _section(_section(BASE, "DeviceInfo", BASE[BASE.index("[DeviceInfo]\n") + 13:BASE.index(
    "LSS_Supported=1")] + "LSS_Supported=1\nCompactPDO=0x3F\nLSS_Type=Server").replace(
    "Granularity=8", "Granularity=0"), "Comments", "Lines=2\nLine1=First comment line\nLine2=Second, with (more) words"
) + "\n[DeviceComissioning]\nNodeID=5\nNodeName=Left axis\nBaudrate=500\nNetNumber=1\nNetworkName=Line 2\n" \
    "CANopenManager=0\nLSS_SerialNumber=1234\n\n[Tools]\nItems=1\nTool1=Configurator\n"
"""The clean EDS with every section CiA 311 has a place for, written as a vendor would (``Granularity=0``,
``CompactPDO``, ``LSS_Type``, a two-line comment, a commissioned node, a ``[Tools]`` section)."""

TOOL_PROPERTIES = xdd().replace(
    b'defaultValue="0" PDOmapping="TPDO"/>',
    b'defaultValue="0" PDOmapping="TPDO" uniqueIDRef="UID_OBJ_2000"/>').replace(
    b"</DeviceIdentity>",
    b'</DeviceIdentity><ApplicationProcess><parameterList><parameter uniqueID="UID_OBJ_2000" access="readWrite">'
    b'<label lang="en">Value 0</label><INT/><property name="CO_storageGroup" value="PERSIST_COMM"/>'
    b'<property name="CO_countLabel" value="VAL"/></parameter></parameterList></ApplicationProcess>')
"""An XDD whose object 0x2000 has a tool's own parameter properties (CANopenEditor writes ``CO_storageGroup`` and
``CO_countLabel`` for CANopenNode)."""

HEADER_PLACES = xdd(file={"formatName": "CANopen", "formatVersion": "1.0", "fileName": "io.xdd", "fileCreator": "Hand",
                         "fileVersion": "1", "supportedLanguages": "en de"}).replace(
    b"<vendorID>0x000004D2</vendorID>", b"<vendorID></vendorID>").replace(
    b"<productName>IO 16</productName>", b"<productName>IO 16</productName><productID/>").replace(
    b"</DeviceIdentity>",
    b'</DeviceIdentity><DeviceFunction><capabilities><characteristicsList><characteristic><characteristicName>'
    b'<label lang="en">Stack</label></characteristicName><characteristicContent><label lang="en">Stack 4.0'
    b'</label></characteristicContent><characteristicContent><label lang="en">CiA 301 4.2</label>'
    b"</characteristicContent></characteristic></characteristicsList></capabilities></DeviceFunction>")
"""An XDD with what CiA 311 holds beside the object list and an EDS mostly not: the ProfileBody's ``formatName``,
``formatVersion`` and ``supportedLanguages``, a DeviceFunction characteristic (CANopenEditor writes the stack's
name there) and empty ``vendorID``/``productID`` elements (CANopenNode's demoDevice.xdd has all of them)."""

UNIQUE_IDS = xdd(pdo=("TPDO",)).replace(
    b'defaultValue="0" PDOmapping="TPDO"/>',
    b'defaultValue="0" PDOmapping="TPDO" uniqueIDRef="UID_Speed"/><CANopenObject index="2100" name="Pair" '
    b'objectType="9" subNumber="2" uniqueIDRef="UID_REC_2100"><CANopenSubObject subIndex="00" name="Count" '
    b'objectType="7" dataType="0005" accessType="ro" defaultValue="1" PDOmapping="no"/><CANopenSubObject '
    b'subIndex="01" name="Left" objectType="7" dataType="0007" accessType="rw" defaultValue="0" PDOmapping="no" '
    b'uniqueIDRef="UID_SUB_210001"/></CANopenObject>').replace(
    b"</DeviceIdentity>",
    b'</DeviceIdentity><ApplicationProcess><parameterList>'
    b'<parameter uniqueID="UID_Speed" access="readWrite"><label lang="en">Value 0</label><INT/></parameter>'
    b'<parameter uniqueID="UID_REC_2100" access="noAccess"><label lang="en">Pair</label><BYTE/></parameter>'
    b'<parameter uniqueID="UID_SUB_210001" access="readWrite"><label lang="en">Left</label><UDINT/></parameter>'
    b"</parameterList></ApplicationProcess>")
"""An XDD whose parameters have their own uniqueIDs (``UID_Speed``; CANopenEditor writes ``UID_OBJ_1000`` for a
VAR, ``UID_SUB_100300`` for a sub-object), which the objects name by ``uniqueIDRef``."""

CASES: list[tuple[str, bytes]] = [("pdo_directions.xdd", xdd()), ("all_features.xdd", ALL_FEATURES),
                                  ("versioned.xdd", VERSIONED), ("header_places.xdd", HEADER_PLACES),
                                  ("unique_ids.xdd", UNIQUE_IDS),
                                  ("eds_sections.eds", EDS_SECTIONS.encode())]
