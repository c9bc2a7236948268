"""Where an XDD/XDC holds each value of an object, and writing a new value there: an attribute of the
CANopenObject/CANopenSubObject, or the element of the parameter it refers to (``uniqueIDRef``) that CiA 311 has for
it (``defaultValue``/``actualValue``, ``allowedValues``/``range``, ``label``, ``denotation``, the IEC type, the
``access`` attribute), as object dictionary editors such as CANopenEditor write them."""

from __future__ import annotations

from lxml import etree

from drivebench.device.formats.eds_rewrite import styled
from drivebench.device.formats.xdd import local
from drivebench.device.formats.xdd_export import IEC_TYPES
from drivebench.device.formats.xdd_splice import Snapshot
from drivebench.device.formats.xdd_tree import (
    communication_body,
    insert,
    namespace_of,
    new_child,
    object_list,
    objects,
    parameter_list,
    parameters,
    read_tree,
    remove,
)
from drivebench.errors import ProfileError
from drivebench.i18n import N_, Text
from drivebench.protocol.datatypes import DATA_TYPE_BY_CODE, DataType

ACCESS = {"const": "const", "ro": "read", "wo": "write", "rw": "readWrite", "rwr": "readWriteInput",
          "rww": "readWriteOutput"}
"""The EDS AccessType as a CiA 311 parameter's ``access``."""
VALUE_ELEMENTS = {"defaultValue": "defaultValue", "actualValue": "actualValue"}
LIMITS = {"lowLimit": "minValue", "highLimit": "maxValue"}
PARAMETER_HELD = {"dataType", "accessType", "defaultValue", "actualValue", "lowLimit", "highLimit", "denotation"}
"""Attributes a parameter-layout file (CANopenEditor) keeps on the object's parameter instead."""


def _styled(attribute: str, old: str | None, new: str) -> str:
    """A value or limit in the style of the text it replaces (a negative number in decimal: the text's digit
    count need not be its type's width); other attributes as written."""
    value = attribute in VALUE_ELEMENTS or attribute in LIMITS
    return styled(old, new) if old is not None and value and not new.lstrip().startswith("-") else new


def _unique_id(element: etree._Element) -> str:
    """The uniqueID DriveBench's export gives an object's parameter (``UID_OBJ_200000``, ``UID_OBJ_1018``)."""
    owner = element.getparent() if element.get("index") is None else element
    index = str(owner.get("index") if owner is not None else "")
    holds_value = not any(local(c) == "CANopenSubObject" for c in element)
    return f"UID_OBJ_{index}{element.get('subIndex') or '00'}" if holds_value else f"UID_OBJ_{index}"


class XddFile:
    """The file's tree, its objects and parameters, and the changes made to it."""

    def __init__(self, original: bytes, source: str) -> None:
        self.root = read_tree(original, source)
        self.snapshot = Snapshot(self.root)
        """The tree as read, so what nobody changed is written as its bytes were."""
        body = communication_body(self.root)
        listing = object_list(body) if body is not None else None
        if listing is None:
            raise ProfileError(Text(N_("no object dictionary: no ProfileBody_CommunicationNetwork_CANopen with a "
                                       "CANopenObjectList")), source=source)
        self.listing = listing
        self.objects = objects(listing)
        self.parameters = parameters(self.root)
        self.parameter_layout = any(
            e.get("uniqueIDRef") and e.get("dataType") is None and not any(local(c) == "CANopenSubObject" for c in e)
            for e in self.objects.values())
        """Whether the file's objects keep their values on parameters (CANopenEditor), not as attributes."""

    def parameter(self, element: etree._Element, create: str | None = None) -> etree._Element | None:
        """The parameter ``element`` names; with ``create`` (a uniqueID) a new one where it names none."""
        found = self.parameters.get(str(element.get("uniqueIDRef"))) if element.get("uniqueIDRef") else None
        listing = parameter_list(self.root)
        if found is not None or create is None or listing is None:
            return found
        namespace = namespace_of(self.root, "parameter", listing)
        found = etree.Element(f"{{{namespace}}}parameter" if namespace else "parameter", uniqueID=create)
        insert(listing, len(listing), found)
        element.set("uniqueIDRef", create)
        self.parameters[create] = found
        return found

    def set_value(self, element: etree._Element, attribute: str, old: str | None, new: str | None,
                  unique_id: str | None = None) -> None:
        """An object attribute's new text (None: removed) where the file holds it; ``unique_id`` names a parameter
        made for it where one is needed and the object names none."""
        parameter = self.parameter(element)
        held = self._held(parameter, attribute)
        if element.get(attribute) is not None or (held is None and not self._on_parameter(element, attribute)):
            if new is None:
                element.attrib.pop(attribute, None)
            else:
                element.set(attribute, _styled(attribute, element.get(attribute) or old, new))
            if held is not None and parameter is not None:  # the parameter says it too: it says the same again
                self._set_held(parameter, held, attribute, old, new)
            return
        if parameter is None:
            parameter = self.parameter(element, unique_id or _unique_id(element))
        if parameter is None:
            element.set(attribute, new or "")
            return
        self._set_held(parameter, held, attribute, old, new)

    def _on_parameter(self, element: etree._Element, attribute: str) -> bool:
        return self.parameter_layout and attribute in PARAMETER_HELD and element.get("dataType") is None

    def _held(self, parameter: etree._Element | None, attribute: str) -> etree._Element | None:
        """The element (or the parameter itself, for ``access``) of ``parameter`` holding ``attribute``."""
        if parameter is None:
            return None
        if attribute == "accessType":
            return parameter if parameter.get("access") is not None else None
        if attribute == "name":
            return next((e for e in parameter if local(e) == "label"), None)
        if attribute == "dataType":
            return next((e for e in parameter if local(e) in IEC_TYPES.values()), None)
        if attribute == "denotation":
            return next((e for e in parameter if local(e) == "denotation"), None)
        if attribute in VALUE_ELEMENTS:
            return next((e for e in parameter if local(e) == VALUE_ELEMENTS[attribute]), None)
        if attribute in LIMITS:
            return next((e for e in parameter.iter() if local(e) == LIMITS[attribute]), None)
        return None

    def _drop(self, held: etree._Element) -> None:
        if local(held) in ("parameter", "parameterTemplate"):
            held.attrib.pop("access", None)
            return
        parent = held.getparent()
        remove(held)
        while parent is not None and local(parent) in ("range", "allowedValues") and not len(parent):
            above = parent.getparent()
            remove(parent)  # no limit left: the range and allowedValues that held them go too
            parent = above

    def _set_held(self, parameter: etree._Element, held: etree._Element | None, attribute: str, old: str | None,
                  new: str | None) -> None:
        if new is None:
            if held is not None:
                self._drop(held)
            return
        if attribute == "accessType":
            parameter.set("access", ACCESS.get(new, new))
        elif attribute == "name":
            (held if held is not None else new_child(self.root, parameter, "label", lang="en")).text = new
        elif attribute == "denotation":
            target = held if held is not None else new_child(self.root, parameter, "denotation")
            label = next((e for e in target if local(e) == "label"), None)
            (label if label is not None else new_child(self.root, target, "label", lang="en")).text = new
        elif attribute == "dataType":
            self._set_type(parameter, held, new)
        elif attribute in VALUE_ELEMENTS:
            target = held if held is not None else new_child(self.root, parameter, VALUE_ELEMENTS[attribute])
            target.set("value", _styled(attribute, target.get("value") or old, new))
        elif attribute in LIMITS:
            target = held if held is not None else self._limit(parameter, LIMITS[attribute])
            target.set("value", _styled(attribute, target.get("value") or old, new))

    def _limit(self, parameter: etree._Element, name: str) -> etree._Element:
        allowed = next((e for e in parameter if local(e) == "allowedValues"), None)
        allowed = allowed if allowed is not None else new_child(self.root, parameter, "allowedValues")
        found = next((e for e in allowed if local(e) == "range"), None)
        found = found if found is not None else new_child(self.root, allowed, "range")
        limit = new_child(self.root, found, name)
        if name == "minValue" and len(found) > 1:  # minValue before maxValue
            found.remove(limit)
            insert(found, 0, limit)
        return limit

    def set_parameter_fact(self, element: etree._Element, fact: str, new: str | None,
                           unique_id: str | None = None) -> None:
        """A description or property of the object's parameter (None: removed)."""
        parameter = self.parameter(element, (unique_id or _unique_id(element)) if new is not None else None)
        if parameter is None:
            return
        if fact == "description":
            found = next((e for e in parameter if local(e) == "description"), None)
            if new is None:
                if found is not None:
                    remove(found)
                return
            (found if found is not None else new_child(self.root, parameter, "description", lang="en")).text = new
            return
        name = fact.removeprefix("property:")
        found = next((e for e in parameter if local(e) == "property" and e.get("name") == name), None)
        if new is None:
            if found is not None:
                remove(found)
        elif found is not None:
            found.set("value", new)
        else:
            new_child(self.root, parameter, "property", name=name, value=new)


    def _set_type(self, parameter: etree._Element, held: etree._Element | None, code: str) -> None:
        """A parameter's IEC type element for the CiA 301 type ``code`` (hex); a type without one (DOMAIN of
        another code) as the object's ``dataType`` attribute, which the import reads first."""
        try:
            data_type = DATA_TYPE_BY_CODE.get(int(code, 16))
        except ValueError:
            data_type = None
        name = IEC_TYPES.get(data_type) if data_type is not None else None
        if name is None or data_type is DataType.DOMAIN:
            owner = next((o for o in self.objects.values() if o.get("uniqueIDRef") == parameter.get("uniqueID")),
                         None)
            if owner is not None:
                owner.set("dataType", code)
            return
        if held is not None:
            held.tag = f"{{{etree.QName(held).namespace}}}{name}" if etree.QName(held).namespace else name
        else:
            new_child(self.root, parameter, name)
