"""Where the EDS keys of a profile's ``extra_sections`` have their place in a CiA 311 XDD, both ways.

* ``[FileInfo]`` <-> the ``ProfileBody`` file attributes (``fileCreator`` = ``CreatedBy`` ...); dates and times are
  written in each format's own form (XDD ``2024-03-05``/``14:05:00``, EDS ``03-05-2024``/``02:05PM``) where that
  loses nothing, else as they were; an EDS date already in the XDD form (``CreationDate=2024-03-05``) would come
  back in the EDS form, so it is also kept as an ``EDS:`` property (below), which an import prefers.
* ``[DeviceInfo]`` NMT/LSS keys <-> the ``CANopenGeneralFeatures``/``CANopenMasterFeatures`` attributes; the
  attributes CiA 306 has no key for (``selfStartingDevice``, ``flyingMaster`` ...) are kept under the key
  :data:`GENERAL_FEATURES`/:data:`MASTER_FEATURES` name (an EDS export writes them; other tools skip them).
* ``[DeviceInfo]`` ``Version_FW``/``Version_HW``/``Version_SW`` <-> the DeviceIdentity ``version`` elements.
* ``[DummyUsage]`` <-> ``dummyUsage``; ``[Comments]`` (``Profile.notes``) <-> DeviceIdentity ``productText``;
  ``[DeviceComissioning]`` <-> ``deviceCommissioning``.
* ``[XDD]`` (a DriveBench section an EDS export writes as it is) holds what CiA 311 has a place for and CiA 306 none:
  the ProfileBody's :data:`BODY_ATTRIBUTES` and the device body's ``DeviceFunction`` (its XML on one line).
  Empty ``vendorID``/``productID`` elements are ``VendorNumber=``/``ProductNumber=`` of ``[DeviceInfo]``.
* Every other key (``CompactPDO``, ``EDSVersion``, ``[Tools]`` ...) has no place: :func:`unplaced` lists them, and the
  export carries them as ``EDS:[Section]Key`` properties of the parameter :data:`FILE_PARAMETER` so a DriveBench
  import gets them back.
"""

from __future__ import annotations

import re
from datetime import datetime

from drivebench.device.profiles.profile import Profile

FILE_PARAMETER = "UID_EDS_FILE"
"""The parameter whose ``EDS:[Section]Key`` properties carry the EDS keys CiA 311 has no place for."""
FILE_INFO = {"fileName": "FileName", "fileCreator": "CreatedBy", "fileCreationDate": "CreationDate",
             "fileCreationTime": "CreationTime", "fileModifiedBy": "ModifiedBy",
             "fileModificationDate": "ModificationDate", "fileModificationTime": "ModificationTime",
             "fileVersion": "FileVersion"}
GENERAL_FEATURES = {"groupMessaging": "GroupMessaging", "dynamicChannels": "DynamicChannelsSupported",
                    "selfStartingDevice": "SelfStartingDevice", "SDORequestingDevice": "SDORequestingDevice",
                    "granularity": "Granularity", "bootUpSlave": "SimpleBootUpSlave",
                    "layerSettingServiceSlave": "LSS_Supported", "ngSlave": "NG_Slave", "ngMaster": "NG_Master",
                    "NrOfNG_MonitoredNodes": "NrOfNG_MonitoredNodes"}
MASTER_FEATURES = {"bootUpMaster": "SimpleBootUpMaster", "flyingMaster": "FlyingMaster", "SDOManager": "SDOManager",
                   "configurationManager": "ConfigurationManager", "layerSettingServiceMaster": "LSS_Master"}
XDD_SECTION = "XDD"
"""The extra section of what an XDD holds beside the object list and an EDS has no key for."""
BODY_ATTRIBUTES = ("formatName", "formatVersion", "supportedLanguages")
"""ProfileBody attributes beside the file attributes; the first body's are kept (CANopenEditor writes both alike)."""
DEVICE_FUNCTION = "DeviceFunction"
"""The key of :data:`XDD_SECTION` holding the device body's DeviceFunction element (characteristicsList ...)."""
NUMBER_FEATURES = {"dynamicChannels", "granularity", "NrOfNG_MonitoredNodes"}
"""Feature attributes holding a number; the others are xsd:boolean (default false)."""
COMMISSIONING = {"nodeID": "NodeID", "nodeName": "NodeName", "actualBaudRate": "Baudrate",
                 "networkNumber": "NetNumber", "networkName": "NetworkName", "CANopenManager": "CANopenManager"}
VERSION_KEY = re.compile(r"^Version_([A-Za-z]*)(?:_\d+)?$")
_PLACED_DEVICE_INFO = {*GENERAL_FEATURES.values(), *MASTER_FEATURES.values()}
_XDD_DATE, _EDS_DATE = "%Y-%m-%d", "%m-%d-%Y"
_XDD_TIME, _EDS_TIME = "%H:%M:%S", "%I:%M%p"


def _converted(text: str, source: str, target: str) -> str | None:
    try:
        return datetime.strptime(text.strip(), source).strftime(target)
    except ValueError:
        return None


def _eds_form(attribute: str, text: str) -> str | None:
    if attribute.endswith("Date"):
        return _converted(text, _XDD_DATE, _EDS_DATE)
    if attribute.endswith("Time") and text.endswith(":00"):
        return _converted(text, _XDD_TIME, _EDS_TIME)
    return None


def _xdd_form(attribute: str, text: str) -> str | None:
    if attribute.endswith("Date"):
        return _converted(text, _EDS_DATE, _XDD_DATE)
    if attribute.endswith("Time"):
        return _converted(text, _EDS_TIME, _XDD_TIME)
    return None


def eds_file_value(attribute: str, text: str) -> str:
    """A ProfileBody file attribute as its [FileInfo] value: an XDD date/time in the EDS form where the way back
    gives the same text, else as written."""
    converted = _eds_form(attribute, text)
    return converted if converted is not None and _xdd_form(attribute, converted) == text else text


def xdd_file_value(attribute: str, text: str) -> str:
    """A [FileInfo] value as its ProfileBody file attribute (the EDS date/time in the XDD form, as above)."""
    converted = _xdd_form(attribute, text)
    return converted if converted is not None and _eds_form(attribute, converted) == text else text


def eds_feature_value(attribute: str, text: str) -> str:
    """A feature attribute as its [DeviceInfo] value: xsd:boolean ``true``/``false`` as ``1``/``0``."""
    if attribute in NUMBER_FEATURES:
        return text
    return {"true": "1", "false": "0"}.get(text.strip().lower(), text)


def xdd_feature_value(attribute: str, text: str) -> str:
    if attribute in NUMBER_FEATURES:
        return text
    return {"1": "true", "0": "false"}.get(text.strip(), text)


def extra(profile: Profile, name: str) -> dict[str, str]:
    for section, keys in profile.extra_sections.items():
        if section.lower() == name.lower():
            return keys
    return {}


def _placed(section: str, key: str, value: str) -> bool:
    kind = section.lower()
    if kind == "fileinfo":  # a date the attribute would give back in another form (ISO in an EDS) has none
        attribute = next((a for a, k in FILE_INFO.items() if k == key), None)
        return attribute is not None and eds_file_value(attribute, xdd_file_value(attribute, value)) == value
    if kind == "deviceinfo":
        empty_identity = key.lower() in ("vendornumber", "productnumber") and not value  # an empty element
        return key in _PLACED_DEVICE_INFO or VERSION_KEY.match(key) is not None or empty_identity
    if kind == "devicecomissioning":
        return key in COMMISSIONING.values()
    return kind in ("dummyusage", XDD_SECTION.lower())


def unplaced(profile: Profile) -> list[tuple[str, str, str]]:
    """The (section, key, value) of ``extra_sections`` CiA 311 has no place for, in file order (and the [FileInfo]
    dates and times its attribute would give back in another form: ``CreationDate=2024-01-15``)."""
    return [(section, key, value) for section, keys in profile.extra_sections.items()
            for key, value in keys.items() if not _placed(section, key, value)]
