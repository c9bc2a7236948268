"""Found by the outside corpus (``benchmarks/outside_corpus.py``): CiA 301 types the model reads as DOMAIN (40/48/
56-bit integers, TIME_OF_DAY, TIME_DIFF) keep their DataType code through EDS -> XDD -> EDS; CiA 311's ``dataType``
attribute holds any CiA 301 code."""

from __future__ import annotations

import pytest
from lxml import etree

from drivebench.device.formats.eds import read_eds
from drivebench.device.formats.eds_export import export_eds
from drivebench.device.formats.eds_ini import parse_ini
from drivebench.device.formats.xdd import read_xdd
from drivebench.device.formats.xdd_export import export_xdd

NS = "{http://www.canopen.org/xml/1.0}"
CODES = {0x2000: 0x0012, 0x2001: 0x001A, 0x2002: 0x000C, 0x2003: 0x000D}
WIDE_TYPES = "\n".join(
    ["[DeviceInfo]", "VendorName=Test", "ProductName=Wide types", "[MandatoryObjects]", "SupportedObjects=1",
     "1=0x1000", "[1000]", "ParameterName=Device type", "DataType=0x0007", "AccessType=ro", "DefaultValue=0",
     "[ManufacturerObjects]", f"SupportedObjects={len(CODES)}",
     *(f"{n}=0x{i:04X}" for n, i in enumerate(CODES, start=1)),
     *(line for index, code in CODES.items() for line in (f"[{index:04X}]", f"ParameterName=Value {index:04X}",
                                                          f"DataType=0x{code:04X}", "AccessType=rw"))]) + "\n"


def test_an_xdd_written_from_an_eds_names_the_files_own_type_code() -> None:
    xdd = export_xdd(read_eds(WIDE_TYPES.encode(), source="wide.eds").profile)
    written = {int(str(o.get("index")), 16): str(o.get("dataType"))
               for o in etree.fromstring(xdd).iter(f"{NS}CANopenObject")}
    assert {index: written[index] for index in CODES} == {index: f"{code:04X}" for index, code in CODES.items()}


@pytest.mark.parametrize("index", list(CODES))
def test_eds_to_xdd_to_eds_keeps_a_data_type_the_model_reads_as_domain(index: int) -> None:
    profile = read_xdd(export_xdd(read_eds(WIDE_TYPES.encode(), source="wide.eds").profile),
                       source="wide.xdd").profile
    back = parse_ini(export_eds(profile), "back.eds")
    assert int(back[f"{index:04X}"].keys["datatype"].value, 16) == CODES[index]
