"""An uploaded XDD/XDC as an XML tree to write over: read as it is (comments, processing instructions and
whitespace kept), where its objects and parameters are, and written back with the file's own prolog (XML
declaration, comments before the root), encoding and BOM."""

from __future__ import annotations

from lxml import etree

from drivebench.device.formats.dcf_patch import file_encoding
from drivebench.device.formats.xdd import local, parse_xml
from drivebench.device.formats.xdd_splice import Snapshot, spliced

Address = tuple[int, int | None]
"""(index, None) for a CANopenObject, (index, subindex) for a CANopenSubObject."""
PARAMETER_ORDER = {"label": 0, "description": 0, "labelRef": 0, "descriptionRef": 0, "conditional": 2,
                   "denotation": 3, "actualValue": 4, "defaultValue": 5, "substituteValue": 6, "allowedValues": 7,
                   "unit": 8, "property": 9}
"""Where a child goes in a CiA 311 ``parameter`` (its type element, any other name, ranks 1)."""


def read_tree(data: bytes, source: str) -> etree._Element:
    """The root of ``data``, checked as :func:`parse_xml` checks an upload, with comments and processing
    instructions kept (a tree written back has them where they were)."""
    parse_xml(data, source)
    parser = etree.XMLParser(resolve_entities=False, no_network=True, huge_tree=False, load_dtd=False,
                             dtd_validation=False, remove_pis=False, remove_comments=False)
    return etree.fromstring(data, parser)


def communication_body(root: etree._Element) -> etree._Element | None:
    return next((e for e in root.iter() if local(e) == "ProfileBody" and body_type(e).startswith(
        "ProfileBody_CommunicationNetwork_CANopen")), None)


def device_bodies(root: etree._Element) -> list[etree._Element]:
    return [e for e in root.iter() if local(e) == "ProfileBody" and body_type(e).startswith(
        "ProfileBody_Device_CANopen")]


def body_type(body: etree._Element) -> str:
    return next((str(v).split(":")[-1] for k, v in body.attrib.items() if etree.QName(k).localname == "type"), "")


def object_list(body: etree._Element) -> etree._Element | None:
    return next((e for e in body.iter() if local(e) == "CANopenObjectList"), None)


def _hex(text: str | None) -> int | None:
    try:
        return int(text or "", 16)
    except ValueError:
        return None


def objects(listing: etree._Element) -> dict[Address, etree._Element]:
    """Each CANopenObject (the first of an index, as the import reads) and CANopenSubObject by address."""
    found: dict[Address, etree._Element] = {}
    for element in listing:
        index = _hex(element.get("index")) if local(element) == "CANopenObject" else None
        if index is None or (index, None) in found:
            continue
        found[(index, None)] = element
        for sub in element:
            number = _hex(sub.get("subIndex")) if local(sub) == "CANopenSubObject" else None
            if number is not None:
                found.setdefault((index, number), sub)
    return found


def parameters(root: etree._Element) -> dict[str, etree._Element]:
    """The device bodies' parameters (and templates) by uniqueID."""
    return {str(e.get("uniqueID")): e for body in device_bodies(root) for e in body.iter()
            if local(e) in ("parameter", "parameterTemplate") and e.get("uniqueID")}


def parameter_list(root: etree._Element) -> etree._Element | None:
    return next((e for body in device_bodies(root) for e in body.iter() if local(e) == "parameterList"), None)


def namespace_of(root: etree._Element, name: str, fallback: etree._Element) -> str | None:
    """The namespace the file gives elements named ``name`` (CANopenEditor writes ``label`` without one and
    ``defaultValue`` with its prefix), else ``fallback``'s."""
    found = next((e for e in root.iter() if local(e) == name), None)
    return etree.QName(found if found is not None else fallback).namespace


def new_child(root: etree._Element, parent: etree._Element, name: str, /, **attributes: str) -> etree._Element:
    """A child ``name`` of ``parent`` in the file's namespace for it, at its CiA 311 place among a parameter's
    children (else last), indented as its siblings are."""
    namespace = namespace_of(root, name, parent)
    element = etree.Element(f"{{{namespace}}}{name}" if namespace else name, attrib=attributes)
    rank = PARAMETER_ORDER.get(name, 1)
    at = next((n for n, child in enumerate(parent) if isinstance(child.tag, str)
               and PARAMETER_ORDER.get(local(child), 1) > rank), len(parent)) if local(parent) in (
        "parameter", "parameterTemplate") else len(parent)
    insert(parent, at, element)
    return element


def _indent_of(element: etree._Element) -> str | None:
    """The whitespace (a line end and the indentation) before ``element``, where it has its own line."""
    previous, parent = element.getprevious(), element.getparent()
    space = previous.tail if previous is not None else parent.text if parent is not None else None
    return space if space is not None and not space.strip() and "\n" in space else None


def _pretty(element: etree._Element, indent: str) -> None:
    """``element``'s children each on their own line, two spaces in from ``indent`` (``element``'s own); text
    that is not whitespace stays as it is."""
    if not len(element) or (element.text is not None and element.text.strip()):
        return
    inner = indent + "  "
    element.text = inner
    for child in element:
        if child.tail is None or not child.tail.strip():
            child.tail = inner
        _pretty(child, inner)
    last = element[-1]
    if last.tail is None or not last.tail.strip():
        last.tail = indent


def insert(parent: etree._Element, at: int, element: etree._Element) -> None:
    """``element`` as child ``at`` of ``parent``, with the whitespace its siblings have (its own children on
    their lines, indented one step further)."""
    outer = _indent_of(parent)
    indent = parent.text if len(parent) and parent.text is not None and not parent.text.strip() else (
        outer + "  " if outer is not None else None)
    if len(parent) == 0:
        if indent is not None:
            parent.text, element.tail = indent, outer
    elif at >= len(parent):
        last = parent[-1]
        element.tail, last.tail = last.tail, indent if indent is not None else last.tail
    else:
        element.tail = indent
    parent.insert(at, element)
    if indent is not None:
        _pretty(element, indent)


def remove(element: etree._Element) -> None:
    """``element`` out of its parent, the whitespace before it going with it (its tail stays for what follows)."""
    parent = element.getparent()
    if parent is None:
        return
    previous = element.getprevious()
    if previous is not None:
        previous.tail = element.tail
    else:
        parent.text = element.tail
    parent.remove(element)


def _skip_back(text: str, end: int) -> int:
    """Where the root's end tag stops: before trailing whitespace, comments and processing instructions."""
    while True:
        stripped = text[:end].rstrip()
        if stripped.endswith("-->") and "<!--" in stripped:
            end = stripped.rindex("<!--")
        elif stripped.endswith("?>") and "<?" in stripped:
            end = stripped.rindex("<?")
        else:
            return len(stripped)


def _root_start(text: str) -> int:
    at = 0
    while True:
        rest = text[at:]
        stripped = rest.lstrip("\ufeff \t\r\n")
        at += len(rest) - len(stripped)
        if stripped.startswith("<?") and "?>" in stripped:
            at += stripped.index("?>") + 2
        elif stripped.startswith("<!--") and "-->" in stripped:
            at += stripped.index("-->") + 3
        else:
            return at


def written(original: bytes, root: etree._Element, snapshot: Snapshot | None = None) -> bytes:
    """``root`` as the file ``original`` was: its text before and after the root element (XML declaration,
    comments) as it was, in its encoding and with its BOM; with the ``snapshot`` of the tree as read, every node
    nobody changed as its bytes were (:mod:`~drivebench.device.formats.xdd_splice`), else the tree serialized."""
    encoding, bom = file_encoding(original)
    declared = root.getroottree().docinfo.encoding
    if bom == b"" and declared and encoding in ("utf-8", "cp1252", "latin-1"):
        encoding = declared
    text = original[len(bom):].decode(encoding, errors="replace")
    start, end = _root_start(text), _skip_back(text, len(text))
    kept = spliced(text, start, root, snapshot) if snapshot is not None else None
    if kept is not None:
        body, end = kept
    else:
        body = etree.tostring(root, encoding="unicode", with_tail=False)
    return bom + (text[:start] + body + text[end:]).encode(encoding, errors="xmlcharrefreplace")
