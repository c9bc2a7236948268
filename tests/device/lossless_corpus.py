"""EDS/DCF files of what real files carry and a regenerated export must keep (issue 34), generated here from the
quirk corpus' clean base (no vendor's file is copied).

Each case is one small file and one edit: the edit test changes that one value (``field`` of object ``address``,
in engineering units) and expects only ``key`` of the section ``section`` to differ in the regenerated export.
``python -m tests.device.lossless_corpus DIR`` writes the files for a look with other tools.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path

from tests.device.quirk_corpus import BASE, Quirk, add, chain, section_key, sub


@dataclass(frozen=True)
class Edit:
    address: tuple[int, int]
    field: str
    value: object
    section: str
    key: str


SPEED = Edit((0x2000, 0), "default", 3500, "2000", "DefaultValue")
"""The edit of cases about another object: the speed limit's default."""


@dataclass(frozen=True)
class LosslessCase:
    name: str
    quirk: Quirk
    edit: Edit = SPEED
    encoding: str = "utf-8"
    suffix: str = ".eds"

    def content(self) -> bytes:
        return self.quirk(BASE).encode(self.encoding)


def listed(block: str, *indices: int) -> Quirk:
    """``block`` added at the end and its objects listed in [ManufacturerObjects]."""
    entries = "".join(f"{5 + n}=0x{index:04X}\n" for n, index in enumerate(indices))
    return chain(sub("4=0x2003\n", f"4=0x2003\n{entries}"),
                 sub("SupportedObjects=4\n1=0x2000", f"SupportedObjects={4 + len(indices)}\n1=0x2000"), add(block))


def typed(code: int, name: str, default: str, low: str | None = None, high: str | None = None) -> Quirk:
    limits = (f"LowLimit={low}\n" if low is not None else "") + (f"HighLimit={high}\n" if high is not None else "")
    return listed(f"[2010]\nParameterName={name}\nObjectType=0x7\nDataType=0x{code:04X}\nAccessType=rw\n"
                  f"DefaultValue={default}\n{limits}PDOMapping=0\n", 0x2010)


CASES = [
    LosslessCase("object-obj-flags", listed(
        "[2010]\nParameterName=Flagged value\nObjectType=0x7\nDataType=0x0006\nAccessType=rw\nDefaultValue=7\n"
        "PDOMapping=0\nObjFlags=0x3\n\n[2011]\nParameterName=Flagged record\nObjectType=0x9\nSubNumber=2\n"
        "ObjFlags=0x1\n\n[2011sub0]\nParameterName=Highest sub-index supported\nObjectType=0x7\nDataType=0x0005\n"
        "AccessType=ro\nDefaultValue=1\nPDOMapping=0\n\n[2011sub1]\nParameterName=Entry\nObjectType=0x7\n"
        "DataType=0x0007\nAccessType=rw\nDefaultValue=0x10\nPDOMapping=0\nObjFlags=0x2\n", 0x2010, 0x2011),
                 Edit((0x2010, 0), "default", 9, "2010", "DefaultValue")),
    LosslessCase("integer24-type", typed(0x10, "Small offset", "-5", "-8388608", "8388607")),
    LosslessCase("integer40-type", typed(0x12, "Long offset", "0x0000000001", "-549755813888", "549755813887")),
    LosslessCase("integer48-type", typed(0x13, "Position 48", "-1")),
    LosslessCase("integer56-type", typed(0x14, "Position 56", "0")),
    LosslessCase("unsigned24-type", typed(0x16, "Counter 24", "0x000100")),
    LosslessCase("unsigned40-type", typed(0x18, "Counter 40", "0x0000000100", "0", "0xFFFFFFFFFF")),
    LosslessCase("unsigned48-type", typed(0x19, "Counter 48", "281474976710655")),
    LosslessCase("unsigned56-type", typed(0x1A, "Counter 56", "0x00000000000001")),
    LosslessCase("real64-type", typed(0x11, "Gain 64", "0.125"), Edit((0x2010, 0), "default", 0.25, "2010",
                                                                     "DefaultValue")),
    LosslessCase("time-of-day-type", typed(0x0C, "Clock", "0x000000000000")),
    LosslessCase("time-difference-type", typed(0x0D, "Interval", "0x00000000")),
    LosslessCase("domain-values-dcf", chain(listed(
        "[2012]\nParameterName=Drive configuration block\nObjectType=0x2\nDataType=0x000F\nAccessType=rw\n"
        "DefaultValue=0x0102\nLowLimit=0x00\nHighLimit=0xFFFF\nParameterValue=0A0B0C0D\n", 0x2012),
        add("[DeviceComissioning]\nNodeID=3\nBaudrate=500\n"), section_key("2000", "ParameterValue", "2500")),
                 Edit((0x2000, 0), "parameter_value", 2600, "2000", "ParameterValue"), suffix=".dcf"),
    LosslessCase("text-default", section_key("2001", "DefaultValue", "see manual")),
    LosslessCase("value-wider-than-type", section_key("1001", "DefaultValue", "0x1FF")),
    LosslessCase("signed-limits-0-to-ff", typed(0x02, "Trim", "0x10", "0x00", "0xFF"),
                 Edit((0x2010, 0), "default", 17, "2010", "DefaultValue")),
    LosslessCase("nodeid-limits", chain(section_key("1400sub1", "LowLimit", "$NODEID+0x200"),
                                        section_key("1400sub1", "HighLimit", "$NODEID+0x27F"))),
    LosslessCase("record-compact-sub-obj", listed(
        "[2014]\nParameterName=Gains\nObjectType=0x9\nCompactSubObj=2\nDataType=0x0006\nAccessType=rw\n"
        "DefaultValue=100\nPDOMapping=0\n", 0x2014)),
    LosslessCase("domain-sub-objects", listed(
        "[2015]\nParameterName=Blocks\nObjectType=0x9\nSubNumber=2\n\n[2015sub0]\nParameterName=Highest sub-index "
        "supported\nObjectType=0x7\nDataType=0x0005\nAccessType=ro\nDefaultValue=1\nPDOMapping=0\n\n[2015sub1]\n"
        "ParameterName=Block 1\nObjectType=0x2\nDataType=0x000F\nAccessType=rw\n", 0x2015)),
    LosslessCase("var-with-stray-sub0", chain(sub("SupportedObjects=5\n1=0x1008", "SupportedObjects=6\n1=0x1008"),
                                              sub("5=0x6040\n", "5=0x6040\n6=0x100B\n"),
                                              add("[100B]\nParameterName=Node-ID\nObjectType=0x7\nDataType=0x0005\n"
                                                  "AccessType=rw\nDefaultValue=0x7F\nPDOMapping=0\n\n[100Bsub0]\n"
                                                  "ParameterName=Node-ID\nDataType=0x0005\nAccessType=ro\n"
                                                  "DefaultValue=0x7F\n")),
                 Edit((0x100B, 0), "default", 0x10, "100B", "DefaultValue")),
    LosslessCase("access-type-hash-comment", section_key("2000", "AccessType", "rw # rw;")),
    LosslessCase("comments-blank-lines-inline", lambda text: "; written by hand\n\n" + text.replace(
        "[2000]\n", "[2000]\n; the speed limit of the axis\n").replace("DefaultValue=3000\n",
                                                                       "DefaultValue = 3000 ; rpm\n\n")),
    LosslessCase("hex-style-lower-case", section_key("2000", "DefaultValue", "0x00000bb8")),
    LosslessCase("hex-style-upper-prefix", section_key("2000", "DefaultValue", "0X0BB8")),
    LosslessCase("cp1252-crlf", lambda text: text.replace("Line1=Clean base", "Line1=\u00b0C \u20ac base")
                 .replace("\n", "\r\n"), encoding="cp1252"),
    LosslessCase("utf16-bom", lambda text: text.replace("\n", "\r\n"), encoding="utf-16"),
    LosslessCase("empty-default-value", chain(section_key("1001", "DefaultValue", ""),
                                              section_key("2001", "DefaultValue", ""))),
    LosslessCase("empty-comments-and-identity-keys", chain(
        sub("Lines=1\nLine1=Clean base of the quirk corpus\n", "Lines=0\n"), section_key("DeviceInfo", "OrderCode", ""),
        section_key("DeviceInfo", "VendorNumber", ""))),
    LosslessCase("sub-number-larger-than-listed", listed(
        "[2016]\nParameterName=Partly listed record\nObjectType=0x9\nSubNumber=4\n\n[2016sub0]\nParameterName="
        "Highest sub-index supported\nObjectType=0x7\nDataType=0x0005\nAccessType=ro\nDefaultValue=3\n"
        "PDOMapping=0\n\n[2016sub3]\nParameterName=Third\nObjectType=0x7\nDataType=0x0007\nAccessType=rw\n"
        "DefaultValue=0x10\nPDOMapping=0\n", 0x2016)),
    LosslessCase("device-info-key-case", chain(section_key("DeviceInfo", "SimpleBootUpSlave", "0"), sub(
        "SimpleBootUpSlave=0\n", "SimpleBootupSlave=0\n"), sub("FileName=", "Filename="))),
    LosslessCase("object-lists-off-their-range", chain(
        sub("SupportedObjects=3\n1=0x1000\n2=0x1001\n3=0x1018\n",
            "SupportedObjects=4\n1=0x1000\n2=0x1001\n3=0x1017\n4=0x1018\n"),
        sub("SupportedObjects=5\n1=0x1008\n2=0x1017\n3=0x1400\n4=0x1800\n5=0x6040\n",
            "SupportedObjects=5\n1=0x1008\n2=0x1400\n3=0x1800\n4=0x6040\n5=0x2003\n"),
        sub("SupportedObjects=4\n1=0x2000\n2=0x2001\n3=0x2002\n4=0x2003\n",
            "SupportedObjects=3\n1=0x2000\n2=0x2001\n3=0x2002\n"))),
    LosslessCase("sub-object-type-record", listed(
        "[2017]\nParameterName=Limits\nObjectType=0x09\nSubNumber=2\n\n[2017sub0]\nParameterName=Highest "
        "sub-index supported\nObjectType=0x09\nDataType=0x0005\nAccessType=ro\nDefaultValue=1\nPDOMapping=0\n\n"
        "[2017sub1]\nParameterName=Torque limit\nObjectType=0x09\nDataType=0x0006\nAccessType=rw\n"
        "DefaultValue=1000\nPDOMapping=0\n", 0x2017)),
    LosslessCase("iso-dates", chain(section_key("FileInfo", "CreationDate", "2024-01-15"),
                                    section_key("FileInfo", "ModificationTime", "14:05"),
                                    section_key("FileInfo", "ModificationDate", "2024-02-01"))),
    LosslessCase("empty-product-name", section_key("DeviceInfo", "ProductName", "")),
    LosslessCase("compact-sub-obj-255", listed(
        "[2018]\nParameterName=Error history\nObjectType=0x8\nCompactSubObj=255\nDataType=0x0007\n"
        "AccessType=ro\nPDOMapping=0\n", 0x2018)),
    LosslessCase("array-without-sub-objects", listed(
        "[2019]\nParameterName=Valve % open\nObjectType=0x8\nDataType=0x0008\nAccessType=rw\nDefaultValue=\n"
        "PDOMapping=0\n", 0x2019)),
    LosslessCase("empty-file-info-key", section_key("FileInfo", "ModifiedBy", "")),
    LosslessCase("empty-parameter-name", listed(
        "[2020]\nParameterName=TPDO\nObjectType=0x8\nSubNumber=2\n\n[2020sub0]\nParameterName=max sub-index\n"
        "ObjectType=0x7\nDataType=0x0005\nAccessType=ro\nDefaultValue=1\nPDOMapping=1\n\n[2020sub1]\nParameterName=\n"
        "ObjectType=0x7\nDataType=0x0005\nAccessType=rw\nDefaultValue=\nPDOMapping=1\n", 0x2020)),
    LosslessCase("listed-without-section", chain(sub("SupportedObjects=5\n1=0x1008", "SupportedObjects=6\n1=0x1008"),
                                                 sub("5=0x6040\n", "5=0x6040\n6=0x6505\n"))),
    LosslessCase("unusable-factor-empty-description", chain(section_key("2001", "Factor", "ERROR"),
                                                            section_key("2001", "Description", ""),
                                                            section_key("2001", "Unit", ""),
                                                            section_key("2002", "Factor", "1"))),
]


def files() -> list[tuple[str, bytes, LosslessCase]]:
    """(file name, bytes, case) of every corpus file."""
    return [(f"{n:02d}-{case.name}{case.suffix}", case.content(), case) for n, case in enumerate(CASES, start=1)]


LOSSLESS_FILES = files()

if __name__ == "__main__":
    target = Path(sys.argv[1] if len(sys.argv) > 1 else "eds_lossless")
    target.mkdir(parents=True, exist_ok=True)
    for name, content, _ in files():
        (target / name).write_bytes(content)
    print(f"wrote {len(CASES)} files to {target}")
