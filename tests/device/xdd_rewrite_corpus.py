"""Small XDD files (written here, no vendor's file copied) in both CiA 311 v1.1 layouts, for the regenerated XDD
written over its file (issue 34): values as CANopenObject attributes, and the object dictionary editors' layout
(CANopenEditor: a ``parameterList`` whose parameters carry label, IEC type, ``defaultValue``, ``allowedValues`` and
``access``, a ``dataTypeList`` with ``array``/``struct``/``varDeclaration``/``subrange``, objects naming their
parameter by ``uniqueIDRef``, a prefixed namespace, ``xmlns=""`` children and ``<x />`` empty tags).
:func:`attribute_xdd` and :func:`parameter_xdd` build one from a list of VAR objects so hypothesis can vary them."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

IEC = {0x0002: "SINT", 0x0003: "INT", 0x0004: "DINT", 0x0005: "USINT", 0x0006: "UINT", 0x0007: "UDINT"}


@dataclass(frozen=True)
class Var:
    """A VAR object 0x2000.. of a generated file: its type code, default text and (optional) limit texts."""

    index: int
    code: int
    default: str
    low: str | None = None
    high: str | None = None


HEADER = """<ProfileHeader xmlns="">
      <ProfileIdentification>CANopen {0} profile</ProfileIdentification>
      <ProfileRevision>1.1</ProfileRevision>
      <ProfileName />
      <ProfileSource />
      <ProfileClassID>{1}</ProfileClassID>
    </ProfileHeader>"""


def attribute_xdd(variables: Sequence[Var], *, newline: str = "\n") -> bytes:
    """An XDD of CiA 311's first layout: each object's values as CANopenObject attributes (limits too)."""
    objects = "".join(
        f'\n          <CANopenObject index="{v.index:04X}" name="Value {v.index:04X}" objectType="7" '
        f'dataType="{v.code:04X}" accessType="rw" defaultValue="{v.default}"'
        + (f' lowLimit="{v.low}"' if v.low is not None else "") + (f' highLimit="{v.high}"' if v.high else "")
        + ' PDOmapping="optional" />' for v in variables)
    text = f"""<?xml version="1.0" encoding="utf-8"?>
<!-- written by hand for DriveBench's tests -->
<ISO15745ProfileContainer xmlns="http://www.canopen.org/xml/1.0" xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance">
  <ISO15745Profile>
    {HEADER.format("device", "Device")}
    <ProfileBody xsi:type="ProfileBody_Device_CANopen" fileName="attr.xdd" fileCreator="Hand"
        fileCreationDate="2024-03-03" fileVersion="1">
      <DeviceIdentity>
        <vendorName>Example IO</vendorName>
        <vendorID>0x000004D2</vendorID>
        <productName>Attr 8</productName>
      </DeviceIdentity>
      <ApplicationProcess>
        <parameterList>
          <parameter uniqueID="UID_OBJ_1000" access="read">
            <label lang="en">Device type</label>
            <description lang="en">CiA 401 device, 8 inputs</description>
            <UDINT />
          </parameter>
        </parameterList>
      </ApplicationProcess>
    </ProfileBody>
  </ISO15745Profile>
  <ISO15745Profile>
    {HEADER.format("communication network", "CommunicationNetwork")}
    <ProfileBody xsi:type="ProfileBody_CommunicationNetwork_CANopen" fileName="attr.xdd" fileCreator="Hand"
        fileCreationDate="2024-03-03" fileVersion="1">
      <ApplicationLayers>
        <CANopenObjectList>
          <CANopenObject index="1000" name="Device type" objectType="7" dataType="0007" accessType="ro"
            defaultValue="0x00030191" PDOmapping="no" uniqueIDRef="UID_OBJ_1000" />
          <CANopenObject index="1018" name="Identity" objectType="9" subNumber="2">
            <CANopenSubObject subIndex="00" name="Highest sub-index" objectType="7" dataType="0005" accessType="ro"
                defaultValue="1" PDOmapping="no" />
            <CANopenSubObject subIndex="01" name="Vendor-ID" objectType="7" dataType="0007" accessType="ro"
                defaultValue="0x000004D2" PDOmapping="no" />
          </CANopenObject>{objects}
        </CANopenObjectList>
      </ApplicationLayers>
      <NetworkManagement>
        <CANopenGeneralFeatures granularity="8" nrOfRxPDO="0" nrOfTxPDO="0" />
        <CANopenMasterFeatures />
      </NetworkManagement>
    </ProfileBody>
  </ISO15745Profile>
</ISO15745ProfileContainer>
"""
    return text.replace("\n", newline).encode()


def _parameter(v: Var) -> str:
    limits = ""
    if v.low is not None or v.high is not None:
        limits = ("\n            <q1:allowedValues>\n              <q1:range>"
                  + (f'\n                <q1:minValue value="{v.low}" />' if v.low is not None else "")
                  + (f'\n                <q1:maxValue value="{v.high}" />' if v.high is not None else "")
                  + "\n              </q1:range>\n            </q1:allowedValues>")
    return f"""
          <q1:parameter uniqueID="UID_OBJ_{v.index:04X}" access="readWrite">
            <label lang="en">Value {v.index:04X}</label>
            <{IEC[v.code]} />
            <q1:defaultValue value="{v.default}" />{limits}
            <q1:property name="CO_storageGroup" value="RAM" />
          </q1:parameter>"""


def parameter_xdd(variables: Sequence[Var], *, newline: str = "\n") -> bytes:
    """An XDD as CANopenEditor writes one: objects with name, objectType, PDOmapping and uniqueIDRef only, their
    type, access, default and limits on the parameter they name."""
    objects = "".join(f'\n          <CANopenObject index="{v.index:04X}" name="Value {v.index:04X}" objectType="7" '
                      f'PDOmapping="optional" uniqueIDRef="UID_OBJ_{v.index:04X}" />' for v in variables)
    text = f"""<?xml version="1.0" encoding="utf-8"?>
<!--File is written by hand for DriveBench's tests, in the style of an object dictionary editor-->
<ISO15745ProfileContainer xmlns:xsd="http://www.w3.org/2001/XMLSchema"
    xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance" xmlns="http://www.canopen.org/xml/1.1">
  <ISO15745Profile>
    {HEADER.format("device", "Device")}
    <ProfileBody xmlns:q1="http://www.canopen.org/xml/1.1" xsi:type="q1:ProfileBody_Device_CANopen"
        formatName="CANopen" formatVersion="1.0" fileName="editor.xdd" fileCreator="Hand"
        fileCreationDate="2024-03-03" fileCreationTime="13:37:54.0000000+02:00" fileVersion="1"
        supportedLanguages="en" xmlns="">
      <q1:DeviceIdentity>
        <q1:vendorName></q1:vendorName>
        <q1:vendorID></q1:vendorID>
        <q1:productName>Editor device</q1:productName>
        <q1:productID></q1:productID>
        <q1:version versionType="FW">0</q1:version>
      </q1:DeviceIdentity>
      <q1:ApplicationProcess>
        <q1:dataTypeList>
          <q1:array name="Store parameters" uniqueID="UID_ARR_1010">
            <q1:subrange lowerLimit="0" upperLimit="1" />
            <UDINT />
          </q1:array>
          <q1:struct name="Identity" uniqueID="UID_REC_1018">
            <q1:varDeclaration name="Highest sub-index supported" uniqueID="UID_RECSUB_101800">
              <USINT />
            </q1:varDeclaration>
            <q1:varDeclaration name="Vendor-ID" uniqueID="UID_RECSUB_101801">
              <UDINT />
            </q1:varDeclaration>
          </q1:struct>
        </q1:dataTypeList>
        <q1:parameterList>
          <q1:parameter uniqueID="UID_OBJ_1000">
            <label lang="en">Device type</label>
            <description lang="en">* bit 0-15: device profile number
* bit 16-31: additional information</description>
            <UDINT />
            <q1:defaultValue value="0x00000000" />
            <q1:property name="CO_storageGroup" value="RODATA" />
          </q1:parameter>
          <q1:parameter uniqueID="UID_OBJ_1010">
            <q1:dataTypeIDRef uniqueIDRef="UID_ARR_1010" />
          </q1:parameter>
          <q1:parameter uniqueID="UID_SUB_101000">
            <label lang="en">Highest sub-index supported</label>
            <USINT />
            <q1:defaultValue value="0x01" />
          </q1:parameter>
          <q1:parameter uniqueID="UID_SUB_101001" access="readWrite">
            <label lang="en">Save all parameters</label>
            <UDINT />
            <q1:defaultValue value="0x00000001" />
          </q1:parameter>
          <q1:parameter uniqueID="UID_OBJ_1018">
            <q1:dataTypeIDRef uniqueIDRef="UID_REC_1018" />
          </q1:parameter>
          <q1:parameter uniqueID="UID_SUB_101800">
            <label lang="en">Highest sub-index supported</label>
            <USINT />
            <q1:defaultValue value="0x01" />
          </q1:parameter>
          <q1:parameter uniqueID="UID_SUB_101801">
            <label lang="en">Vendor-ID</label>
            <UDINT />
            <q1:defaultValue value="0x00000000" />
          </q1:parameter>{"".join(_parameter(v) for v in variables)}
        </q1:parameterList>
      </q1:ApplicationProcess>
    </ProfileBody>
  </ISO15745Profile>
  <ISO15745Profile>
    {HEADER.format("communication network", "CommunicationNetwork")}
    <ProfileBody xmlns:q1="http://www.canopen.org/xml/1.1" xsi:type="q1:ProfileBody_CommunicationNetwork_CANopen"
        formatName="CANopen" formatVersion="1.0" fileName="editor.xdd" fileCreator="Hand"
        fileCreationDate="2024-03-03" fileCreationTime="13:37:54.0000000+02:00" fileVersion="1"
        supportedLanguages="en">
      <ApplicationLayers>
        <CANopenObjectList>
          <CANopenObject index="1000" name="Device type" objectType="7" PDOmapping="no" uniqueIDRef="UID_OBJ_1000" />
          <CANopenObject index="1010" name="Store parameters" objectType="8" uniqueIDRef="UID_OBJ_1010" subNumber="2">
            <CANopenSubObject subIndex="00" name="Highest sub-index supported" objectType="7" PDOmapping="no"
                uniqueIDRef="UID_SUB_101000" />
            <CANopenSubObject subIndex="01" name="Save all parameters" objectType="7" PDOmapping="no"
                uniqueIDRef="UID_SUB_101001" />
          </CANopenObject>
          <CANopenObject index="1018" name="Identity" objectType="9" uniqueIDRef="UID_OBJ_1018" subNumber="2">
            <CANopenSubObject subIndex="00" name="Highest sub-index supported" objectType="7" PDOmapping="no"
                uniqueIDRef="UID_SUB_101800" />
            <CANopenSubObject subIndex="01" name="Vendor-ID" objectType="7" PDOmapping="no"
                uniqueIDRef="UID_SUB_101801" />
          </CANopenObject>{objects}
        </CANopenObjectList>
      </ApplicationLayers>
      <TransportLayers>
        <PhysicalLayer>
          <baudRate defaultValue="1000 Kbps">
            <supportedBaudRate value="250 Kbps" />
            <supportedBaudRate value="1000 Kbps" />
          </baudRate>
        </PhysicalLayer>
      </TransportLayers>
      <NetworkManagement>
        <CANopenGeneralFeatures granularity="8" nrOfRxPDO="0" nrOfTxPDO="0" />
        <CANopenMasterFeatures />
      </NetworkManagement>
    </ProfileBody>
  </ISO15745Profile>
</ISO15745ProfileContainer>"""
    return text.replace("\n", newline).encode()


VARS = (Var(0x2000, 0x0006, "0x0BB8", "0", "0x1F40"), Var(0x2001, 0x0003, "-5"), Var(0x2002, 0x0007, "0x0000ffff"))
ATTRIBUTES = attribute_xdd(VARS)
PARAMETERS = parameter_xdd(VARS)
REWRITE_FILES: list[tuple[str, bytes]] = [("attributes.xdd", ATTRIBUTES), ("parameters.xdd", PARAMETERS),
                                          ("parameters-crlf.xdd", parameter_xdd(VARS, newline="\r\n"))]
MARKUP = ATTRIBUTES.replace(
    b'<description lang="en">CiA 401 device, 8 inputs</description>',
    b'<description lang="en"><![CDATA[CiA 401 <device>]]>, &#x38; inputs</description>').replace(
    b"<CANopenObjectList>", b"<CANopenObjectList>\n          <!-- objects: <2000> and up -->").replace(
    b'<CANopenObject index="2001" name="Value 2001"', b"<CANopenObject index='2001' name='Value > 2001'").replace(
    b'<CANopenMasterFeatures />', b"<CANopenMasterFeatures></CANopenMasterFeatures><?tool keep?>")
"""The attribute layout with markup a scanner of tags must step over: CDATA with ``<``, a character reference, a
comment in the object list, single quotes, ``>`` in an attribute value, ``<x></x>`` and a processing instruction."""
REWRITE_FILES.append(("markup.xdd", MARKUP))
