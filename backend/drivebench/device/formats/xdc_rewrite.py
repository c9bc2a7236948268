"""A node's XDC written over the XDD/XDC its profile was read from: the configured values as each object's
``actualValue`` where the file holds values (an attribute, or the parameter's ``actualValue`` element), the node id
(and bit rate) in ``deviceCommissioning``; every other byte is the file's (the XDC twin of
:mod:`~drivebench.device.formats.dcf_patch`)."""

from __future__ import annotations

from collections.abc import Mapping

from lxml import etree

from drivebench.device.formats.eds_export import Address, node_value
from drivebench.device.formats.xdd import local
from drivebench.device.formats.xdd_rewrite import rewrite_xdd
from drivebench.device.formats.xdd_tree import communication_body, new_child
from drivebench.device.profiles.profile import Profile, Value


def with_values(profile: Profile, values: Mapping[Address, Value], node_id: int | None) -> Profile:
    """``profile`` whose objects hold the values an XDC of the node gives them as their ParameterValue (the file's
    kept text of a changed one dropped, as an edit drops it)."""
    objects = []
    for entry in profile.objects:
        value = node_value(entry, values, node_id, True)
        if value is None or value == entry.parameter_value:
            objects.append(entry)
            continue
        texts = {k: v for k, v in (entry.value_texts or {}).items() if k != "ParameterValue"} or None
        objects.append(entry.model_copy(update={"parameter_value": value, "value_texts": texts}))
    return profile.model_copy(update={"objects": objects})


def commission(root: etree._Element, profile: Profile, node_id: int | None, baud_kbit: int | None) -> None:
    """The node id (and bit rate) in the communication body's ``deviceCommissioning``, made as the XDC export
    makes it where the file has none."""
    body = communication_body(root)
    management = next((e for e in body.iter() if local(e) == "NetworkManagement"), None) if body is not None \
        else None
    if management is None:
        return
    element = next((e for e in management if local(e) == "deviceCommissioning"), None)
    if element is None:
        element = new_child(root, management, "deviceCommissioning", nodeID=str(node_id or 1),
                            nodeName=profile.identity.product_name, networkNumber="1", networkName="",
                            CANopenManager="false")
    elif node_id is not None:
        element.set("nodeID", str(node_id))
    if baud_kbit is not None:
        element.set("actualBaudRate", f"{baud_kbit} Kbps")


def rewrite_xdc(profile: Profile, original: bytes, source: str, *, node_id: int | None,
                values: Mapping[Address, Value], baud_kbit: int | None = None) -> bytes:
    """The XDC of a node of ``profile`` (raw ``values`` by address) written over ``original``."""
    return rewrite_xdd(with_values(profile, values, node_id), original, source,
                       finish=lambda root: commission(root, profile, node_id, baud_kbit))
