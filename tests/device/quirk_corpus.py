"""A regression corpus of quirky EDS/DCF files, generated here (no vendor's file is copied).

Each case starts from one clean CiA 402 servo description (``BASE``) and applies one quirk seen in device
descriptions from drive, inverter and I/O makers and from generators (CANopenNode/CANopenEditor, lely dcfgen,
CanFestival). ``warns`` is words of the warning the import must give (with a line), None for a quirk real tools read
without comment (encodings, line ends, case, inline comments...), which must give no warning at all.
``python -m tests.device.quirk_corpus DIR`` writes the files for a look with other tools.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

BASE = """\
[FileInfo]
FileName=servo.eds
FileVersion=1
FileRevision=2
EDSVersion=4.0
Description=Compact servo drive
CreationTime=09:00AM
CreationDate=01-15-2024
CreatedBy=Hand written

[DeviceInfo]
VendorName=Example Drives
VendorNumber=0x000004D2
ProductName=Servo 400
ProductNumber=0x00000190
RevisionNumber=0x00010002
OrderCode=SV-400
BaudRate_10=0
BaudRate_20=0
BaudRate_50=0
BaudRate_125=1
BaudRate_250=1
BaudRate_500=1
BaudRate_800=0
BaudRate_1000=1
SimpleBootUpMaster=0
SimpleBootUpSlave=1
Granularity=8
DynamicChannelsSupported=0
GroupMessaging=0
NrOfRXPDO=1
NrOfTXPDO=1
LSS_Supported=1

[DummyUsage]
Dummy0001=0
Dummy0002=1

[Comments]
Lines=1
Line1=Clean base of the quirk corpus

[MandatoryObjects]
SupportedObjects=3
1=0x1000
2=0x1001
3=0x1018

[OptionalObjects]
SupportedObjects=5
1=0x1008
2=0x1017
3=0x1400
4=0x1800
5=0x6040

[ManufacturerObjects]
SupportedObjects=4
1=0x2000
2=0x2001
3=0x2002
4=0x2003

[1000]
ParameterName=Device type
ObjectType=0x7
DataType=0x0007
AccessType=ro
DefaultValue=0x00020192
PDOMapping=0

[1001]
ParameterName=Error register
ObjectType=0x7
DataType=0x0005
AccessType=ro
DefaultValue=0
PDOMapping=1

[1008]
ParameterName=Manufacturer device name
ObjectType=0x7
DataType=0x0009
AccessType=const
DefaultValue=Servo 400
PDOMapping=0

[1017]
ParameterName=Producer heartbeat time
ObjectType=0x7
DataType=0x0006
AccessType=rw
DefaultValue=0
LowLimit=0
HighLimit=60000
PDOMapping=0

[1018]
ParameterName=Identity object
ObjectType=0x9
SubNumber=3

[1018sub0]
ParameterName=Highest sub-index supported
ObjectType=0x7
DataType=0x0005
AccessType=ro
DefaultValue=2
PDOMapping=0

[1018sub1]
ParameterName=Vendor-ID
ObjectType=0x7
DataType=0x0007
AccessType=ro
DefaultValue=0x000004D2
PDOMapping=0

[1018sub2]
ParameterName=Product code
ObjectType=0x7
DataType=0x0007
AccessType=ro
DefaultValue=0x00000190
PDOMapping=0

[1400]
ParameterName=RPDO1 communication parameter
ObjectType=0x9
SubNumber=2

[1400sub0]
ParameterName=Highest sub-index supported
ObjectType=0x7
DataType=0x0005
AccessType=ro
DefaultValue=2
PDOMapping=0

[1400sub1]
ParameterName=COB-ID used by RPDO
ObjectType=0x7
DataType=0x0007
AccessType=rw
DefaultValue=$NODEID+0x200
PDOMapping=0

[1800]
ParameterName=TPDO1 communication parameter
ObjectType=0x9
SubNumber=2

[1800sub0]
ParameterName=Highest sub-index supported
ObjectType=0x7
DataType=0x0005
AccessType=ro
DefaultValue=2
PDOMapping=0

[1800sub1]
ParameterName=COB-ID used by TPDO
ObjectType=0x7
DataType=0x0007
AccessType=rw
DefaultValue=$NODEID+0x180
PDOMapping=0

[2000]
ParameterName=Speed limit
ObjectType=0x7
DataType=0x0007
AccessType=rw
DefaultValue=3000
LowLimit=0
HighLimit=6000
PDOMapping=1

[2001]
ParameterName=Position offset
ObjectType=0x7
DataType=0x0004
AccessType=rw
DefaultValue=0
LowLimit=-100000
HighLimit=100000
PDOMapping=1

[2002]
ParameterName=Current gain
ObjectType=0x7
DataType=0x0008
AccessType=rw
DefaultValue=1.5
PDOMapping=0

[2003]
ParameterName=Torque trim
ObjectType=0x7
DataType=0x0003
AccessType=rw
DefaultValue=0
LowLimit=-1000
HighLimit=1000
PDOMapping=0

[6040]
ParameterName=Controlword
ObjectType=0x7
DataType=0x0006
AccessType=rww
DefaultValue=0
PDOMapping=1
"""

Quirk = Callable[[str], str]


@dataclass(frozen=True)
class Case:
    name: str
    quirk: Quirk
    warns: str | None
    encoding: str = "utf-8"
    suffix: str = ".eds"

    def content(self) -> bytes:
        text = self.quirk(BASE)
        if self.encoding == "utf-8-sig":
            return b"\xef\xbb\xbf" + text.encode("utf-8")
        return text.encode(self.encoding)


def sub(old: str, new: str, count: int = 1) -> Quirk:
    """Replace ``old`` by ``new`` (``old`` must be in the base: a typo would test nothing)."""
    def apply(text: str) -> str:
        assert old in text, old
        return text.replace(old, new, count)
    return apply


def section_key(section: str, key: str, value: str | None) -> Quirk:
    """Set (or with None remove) ``key`` in ``[section]``."""
    def apply(text: str) -> str:
        head = f"[{section}]\n"
        start = text.index(head) + len(head)
        end = text.find("\n[", start)
        end = len(text) if end < 0 else end
        body = [line for line in text[start:end].split("\n") if not line.lower().startswith(key.lower() + "=")]
        blank = 0
        while body and body[-1] == "":
            body.pop()
            blank += 1
        if value is not None:
            body.append(f"{key}={value}")
        return text[:start] + "\n".join(body) + "\n" * blank + text[end:]
    return apply


def chain(*quirks: Quirk) -> Quirk:
    def apply(text: str) -> str:
        for quirk in quirks:
            text = quirk(text)
        return text
    return apply


def add(block: str) -> Quirk:
    return lambda text: text + "\n" + block


LIMITS = [
    Case("signed-limits-on-unsigned32", chain(section_key("2000", "LowLimit", "0x80000000"),
                                              section_key("2000", "HighLimit", "0x7FFFFFFF")),
         "limits dropped: LowLimit 0x80000000 > HighLimit 0x7FFFFFFF"),
    Case("hex-low-limit-of-integer32", section_key("2001", "LowLimit", "0x80000000"),
         "read as -2147483648: the type is INTEGER32"),
    Case("high-limit-ffffffff-on-unsigned16", section_key("1017", "HighLimit", "0xFFFFFFFF"),
         "does not fit UNSIGNED16 (0..65535): read as 65535"),
    Case("high-limit-ffffffff-on-integer16", section_key("2003", "HighLimit", "0xFFFFFFFF"), "two's complement"),
    Case("decimal-limit-too-big-integer16", section_key("2003", "HighLimit", "70000"),
         "does not fit INTEGER16 (-32768..32767): read as 32767"),
    Case("negative-low-limit-unsigned", section_key("1017", "LowLimit", "-1"), "read as 0"),
    Case("low-limit-none", section_key("2000", "LowLimit", "none"), "'none' read as no limit"),
    Case("limits-swapped", chain(section_key("2001", "LowLimit", "100"), section_key("2001", "HighLimit", "-100")),
         "limits dropped: LowLimit 100 > HighLimit -100"),
    Case("limit-with-unit-text", section_key("2000", "HighLimit", "6000 rpm"), "text after the number ignored"),
    Case("hex-high-limit-all-ones-integer32", section_key("2001", "HighLimit", "0xFFFFFFFF"),
         "read as -1: the type is INTEGER32"),
]
VALUES = [
    Case("nodeid-constant-first", section_key("1800sub1", "DefaultValue", "0x180+$NODEID"), None),
    Case("nodeid-spaced", section_key("1800sub1", "DefaultValue", "$NODEID + 0x180"), None),
    Case("nodeid-in-a-sum", section_key("1400sub1", "DefaultValue", "0x100+$NODEID+0x100"), None),
    Case("nodeid-lower-case", section_key("1400sub1", "DefaultValue", "$nodeid+0x200"), None),
    Case("default-with-trailing-text", section_key("2000", "DefaultValue", "3000rpm"),
         "text after the number ignored"),
    Case("default-octal-leading-zero", section_key("2000", "DefaultValue", "0100"), "read as octal 64"),
    Case("default-decimal-leading-zeros", section_key("2000", "DefaultValue", "0099"), "read as decimal 99"),
    Case("default-float-for-integer", section_key("2000", "DefaultValue", "3000.0"), "read as the integer 3000"),
    Case("real-with-decimal-comma", section_key("2002", "DefaultValue", "1,5"), "decimal comma"),
    Case("real-as-ieee-hex", section_key("2002", "DefaultValue", "0x3FC00000"), None),
    Case("real-exponent", section_key("2002", "DefaultValue", "1.5E+00"), None),
    Case("upper-case-hex-prefix", section_key("1000", "DefaultValue", "0X00020192"), None),
    Case("text-in-parameter-value", section_key("2000", "ParameterValue", "fast"), "is not a number: dropped"),
    Case("default-too-big-for-unsigned8", section_key("1001", "DefaultValue", "300"), "does not fit UNSIGNED8"),
    Case("negative-default-of-unsigned32", section_key("2000", "DefaultValue", "-1"),
         "read as 0xFFFFFFFF: the type is UNSIGNED32"),
    Case("boolean-true-text", add("[2004]\nParameterName=Enable brake\nDataType=0x0001\nAccessType=rw\n"
                                  "DefaultValue=TRUE\n"), "[2004] is in no object list"),
    Case("octet-string-not-hex", add("[2005]\nParameterName=Key\nDataType=0x000A\nAccessType=rw\n"
                                     "DefaultValue=secret\n"), "not hexadecimal"),
    Case("bad-nodeid-formula", section_key("1800sub1", "DefaultValue", "$NODEID*4"), "not a sum"),
    Case("empty-default", section_key("2000", "DefaultValue", ""), None),
]
STRUCTURE = [
    Case("no-product-name", section_key("DeviceInfo", "ProductName", None), "has no ProductName=: named"),
    Case("no-vendor-name", section_key("DeviceInfo", "VendorName", None), "has no VendorName="),
    Case("supported-objects-too-many", section_key("ManufacturerObjects", "SupportedObjects", "6"),
         "SupportedObjects=6 but [ManufacturerObjects] lists 4"),
    Case("supported-objects-too-few", section_key("OptionalObjects", "SupportedObjects", "2"),
         "SupportedObjects=2 but [OptionalObjects] lists 5"),
    Case("sub-number-wrong", section_key("1018", "SubNumber", "5"), "SubNumber=5 but object 0x1018 has 3"),
    Case("no-sub-number", section_key("1400", "SubNumber", None), "has no SubNumber="),
    Case("datatype-0x0023-identity", section_key("2000", "DataType", "0x0023"), "(IDENTITY) is not a CiA 301"),
    Case("datatype-deftype-in-file", chain(section_key("2000", "DataType", "0x0040"),
                                           add("[0040]\nParameterName=UNSIGNED32 alias\nObjectType=0x5\n"
                                               "SubNumber=2\n\n[0040sub1]\nParameterName=Type\nDataType=0x0007\n"
                                               "AccessType=ro\nDefaultValue=0x0007\n")),
         "is defined in [0040sub1] (sub 1): read as UNSIGNED32"),
    Case("var-with-sub-objects", add("[2001sub1]\nParameterName=Stray\nDataType=0x0005\nAccessType=ro\n"),
         "is a VAR but has sub-object sections"),
    Case("var-with-stray-sub0", chain(sub("SupportedObjects=5\n1=0x1008", "SupportedObjects=6\n1=0x1008"),
                                      sub("5=0x6040\n", "5=0x6040\n6=0x100B\n"),
                                      add("[100B]\nParameterName=Node-ID\nObjectType=0x7\nDataType=0x0005\n"
                                          "AccessType=rw\nDefaultValue=0x7F\nPDOMapping=0\n\n[100Bsub0]\n"
                                          "ParameterName=Node-ID\nObjectType=0x7\nDataType=0x0005\nAccessType=ro\n"
                                          "DefaultValue=0x7F\nPDOMapping=0\n")),
         "they are skipped, the VAR is read"),
    Case("access-type-hash-comment", section_key("2000", "AccessType", "rw # rw;"),
         "the text from '#' on is a comment"),
    Case("listed-without-section", sub("4=0x2003\n", "4=0x2003\n5=0x2010\n"), "0x2010 is listed but has no"),
    Case("listed-twice", sub("4=0x2003\n", "4=0x2003\n5=0x2000\n"), "listed twice"),
    Case("listed-index-out-of-range", sub("4=0x2003\n", "4=0x2003\n5=0x0020\n"), "outside 0x1000..0xFFFF"),
    Case("sub-without-object", add("[2100sub1]\nParameterName=Orphan\nDataType=0x0005\nAccessType=rw\n"),
         "belongs to no object section [2100]"),
    Case("no-mandatory-objects-list", sub("[MandatoryObjects]\nSupportedObjects=3\n1=0x1000\n2=0x1001\n3=0x1018\n",
                                          ""), "[1000] is in no object list"),
    Case("no-object-lists-at-all", lambda text: text.replace("[MandatoryObjects]", "[MandatoryObjectsOld]").replace(
        "[OptionalObjects]", "[OptionalObjectsOld]").replace("[ManufacturerObjects]", "[ManufacturerObjectsOld]"),
        "every object section of the file is read"),
    Case("missing-access-type", section_key("2000", "AccessType", None), "has no AccessType=: read as ro"),
    Case("access-type-words", section_key("2000", "AccessType", "readwrite"), "read as rw"),
    Case("access-type-upper-case", section_key("2000", "AccessType", "RW"), None),
    Case("missing-data-type", section_key("2000", "DataType", None), "has no DataType=: read as DOMAIN"),
    Case("missing-parameter-name", section_key("2003", "ParameterName", None), "named 'Object 0x2003'"),
    Case("object-type-deftype-at-data-index", section_key("2003", "ObjectType", "0x5"), "type definition"),
    Case("object-type-decimal", section_key("2003", "ObjectType", "7"), None),
    Case("object-type-missing", section_key("2003", "ObjectType", None), None),
    Case("factor-zero", section_key("2000", "Factor", "0"), "no usable factor"),
    Case("comments-lines-count-wrong", sub("Lines=1\n", "Lines=3\n"), "Lines=3 but [Comments] has 1"),
    Case("nr-of-rxpdo-text", sub("NrOfRXPDO=1\n", "NrOfRXPDO=one\n"), "'one' is not a number"),
    Case("baud-rate-yes", sub("BaudRate_500=1\n", "BaudRate_500=yes\n"), "read as 0 (not supported)"),
    Case("pdo-mapping-text", section_key("2000", "PDOMapping", "yes"), "read as 0 (not mappable)"),
    Case("obj-flags-text", section_key("1018", "ObjFlags", "none"), "'none' is not a number"),
    Case("compact-sub-obj-out-of-range", add("[2006]\nParameterName=Table\nObjectType=0x8\nCompactSubObj=300\n"
                                            "DataType=0x0005\nAccessType=rw\n"), "CompactSubObj=300 is outside"),
    Case("compact-and-sub-sections", add("[2007]\nParameterName=Mixed\nObjectType=0x8\nCompactSubObj=2\n"
                                        "DataType=0x0005\nAccessType=rw\nSubNumber=1\n\n[2007sub0]\n"
                                        "ParameterName=Count\nDataType=0x0005\nAccessType=ro\n"),
         "has CompactSubObj and sub-object sections"),
]
TEXT = [
    Case("utf8-bom", lambda text: text, None, encoding="utf-8-sig"),
    Case("cp1252-degree-and-euro", sub("Line1=Clean base", "Line1=\u00b0C, \u20ac, \u00e4 base"), None,
         encoding="cp1252"),
    Case("latin1-umlauts", sub("VendorName=Example Drives", "VendorName=M\u00fcller Antriebe"), None,
         encoding="latin-1"),
    Case("utf16-le-bom", lambda text: text.replace("\n", "\r\n"), None, encoding="utf-16"),
    Case("utf16-le-no-bom", lambda text: text, None, encoding="utf-16-le"),
    Case("utf16-be-no-bom", sub("VendorName=Example Drives", "VendorName=M\u00fcller Antriebe"), None,
         encoding="utf-16-be"),
    Case("utf32-le-bom", lambda text: text, None, encoding="utf-32"),
    Case("crlf-line-ends", lambda text: text.replace("\n", "\r\n"), None),
    Case("cr-line-ends", lambda text: text.replace("\n", "\r"), None),
    Case("no-final-newline", lambda text: text.rstrip("\n"), None),
    Case("dos-eof-mark", lambda text: text + "\x1a", None),
    Case("duplicate-key", sub("AccessType=rww\n", "AccessType=rww\naccesstype=ro\n"),
         "the first value 'rww' is kept"),
    Case("duplicate-section", add("[6040]\nUnit=-\n"), "duplicate section [6040]"),
    Case("comment-lines-and-hash", lambda text: "; generated\n# by a tool\n" + text.replace(
        "[1000]\n", "[1000]\n;StorageLocation=ROM\n"), None),
    Case("inline-comments", sub("DefaultValue=3000\n", "DefaultValue=3000 ; rpm\n"), None),
    Case("section-header-comment", sub("[2000]\n", "[2000] ; speed\n"), None),
    Case("keys-lower-case", lambda text: text.replace("ParameterName=", "parametername=").replace(
        "DataType=", "datatype="), None),
    Case("keys-upper-case", lambda text: text.replace("AccessType=", "ACCESSTYPE="), None),
    Case("spaces-around-equals", lambda text: text.replace("DefaultValue=", "DefaultValue = "), None),
    Case("tabs-around-values", lambda text: text.replace("PDOMapping=", "PDOMapping=\t"), None),
    Case("sections-lower-case", lambda text: text.replace("[1018sub", "[1018SUB").replace("[DeviceInfo]",
                                                                                          "[deviceinfo]"), None),
    Case("sub-index-zero-padded", lambda text: text.replace("[1018sub1]", "[1018sub01]"), None),
    Case("colon-instead-of-equals", sub("Granularity=8\n", "Granularity: 8\n"), "'key: value' read as"),
    Case("key-before-first-section", lambda text: "Tool=Generator 1.0\n" + text, "before the first [section]"),
    Case("stray-control-character", sub("[1000]\n", "\x07\n[1000]\n"), "binary junk"),
    Case("line-without-equals", sub("[1000]\n", "[1000]\nsome words\n"), "no '=' in"),
    Case("header-without-bracket", sub("[2003]\n", "[2003\n"), "has no ']'"),
]
SECTIONS = [
    Case("compact-sub-obj-with-names-values", chain(sub("4=0x2003\n", "4=0x2003\n5=0x2008\n"), sub(
        "SupportedObjects=4\n1=0x2000", "SupportedObjects=5\n1=0x2000"), add(
        "[2008]\nParameterName=Analog inputs\nObjectType=0x8\nCompactSubObj=3\nDataType=0x0003\nAccessType=ro\n"
        "PDOMapping=1\n\n[2008Name]\nNrOfEntries=2\n1=Input left\n3=Input right\n\n[2008Value]\nNrOfEntries=1\n"
        "2=-5\n\n[2008Denotation]\nNrOfEntries=1\n1=Oven top\n")), None),
    Case("object-links", add("[2000ObjectLinks]\nObjectLinks=2\n1=0x2001\n2=0x2002\n"), None),
    Case("dynamic-channels", add("[DynamicChannels]\nNrOfSeg=1\nType1=0x0007\nDir1=ro\nRange1=0xA080-0xA0BF\n"
                                 "PPOffset1=0\n"), None),
    Case("tools-sections", add("[Tools]\nItems=1\n\n[Tool1]\nName=Configurator\nCommand=cfg.exe $EDS\n"), None),
    Case("vendor-section", add("[Vendor.ExampleDrives]\nFirmwareFamily=SV4\nChecksum=0x5AA5\n"), None),
    Case("domain-upload-download-file", add("[2009]\nParameterName=Firmware\nObjectType=0x2\nDataType=0x000F\n"
                                           "AccessType=rw\nUploadFile=fw_read.bin\nDownloadFile=fw.bin\n"),
         "in no object list"),
    Case("dcf-node-commissioning", chain(add("[DeviceComissioning]\nNodeID=5\nNodeName=Axis X\nBaudrate=500\n"
                                             "NetNumber=1\nNetworkName=Line 1\nCANopenManager=0\n"),
                                         section_key("1800sub1", "ParameterValue", "$NODEID+0x180"),
                                         section_key("2000", "ParameterValue", "2500"),
                                         section_key("2000", "Denotation", "Axis X speed limit")), None,
         suffix=".dcf"),
    Case("canopennode-style", lambda text: text.replace("ObjectType=0x7\n", "ObjectType=0x7\n;StorageLocation=RAM\n")
         .replace("[FileInfo]\n", "[FileInfo]\nLastEDS=\n"), None),
    Case("canfestival-style-names", sub("[OptionalObjects]", "[OptionalObjects]\n; CanFestival writes this"), None),
    Case("lely-dcfgen-empty-values", chain(section_key("2000", "ParameterValue", ""),
                                           section_key("2001", "ParameterValue", "0x0")), None, suffix=".dcf"),
]
CASES = LIMITS + VALUES + STRUCTURE + TEXT + SECTIONS


def files() -> list[tuple[str, bytes, Case]]:
    """(file name, bytes, case) of every corpus file."""
    return [(f"{n:02d}-{case.name}{case.suffix}", case.content(), case) for n, case in enumerate(CASES, start=1)]


CORPUS_FILES = files()

if __name__ == "__main__":
    target = Path(sys.argv[1] if len(sys.argv) > 1 else "eds_quirks")
    target.mkdir(parents=True, exist_ok=True)
    for name, content, _ in files():
        (target / name).write_bytes(content)
    print(f"wrote {len(CASES)} files to {target}")
