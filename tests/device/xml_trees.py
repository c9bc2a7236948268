"""XML files compared as trees: what differs between two files, element by element (whitespace between elements
is no difference), to check that a regenerated XDD changes only what was edited."""

from __future__ import annotations

from collections import Counter

from lxml import etree

_KEYS = ("index", "subIndex", "uniqueID")


def tree_facts(content: bytes) -> Counter[tuple[str, str, str]]:
    """Each element's attributes and text as (path, name, value); the path names each element by its namespace,
    tag and ``index``/``subIndex``/``uniqueID`` (else its place among its like), so moved or retagged elements
    differ too. Whitespace between elements is no fact."""
    facts: Counter[tuple[str, str, str]] = Counter()

    def walk(element: etree._Element, path: str) -> None:
        seen: Counter[str] = Counter()
        for child in element:
            if not isinstance(child.tag, str):
                facts[(path, "comment", str(child.text))] += 1
                continue
            own = next((f"{k}={child.get(k)}" for k in _KEYS if child.get(k) is not None), None)
            seen[child.tag] += 1
            here = f"{path}/{child.tag}[{own or seen[child.tag]}]"
            for name, value in child.attrib.items():
                facts[(here, f"@{name}", str(value))] += 1
            if child.text and child.text.strip():
                facts[(here, "#text", child.text.strip())] += 1
            walk(child, here)

    root = etree.fromstring(content)
    wrapper = etree.Element("document")
    wrapper.append(etree.fromstring(etree.tostring(root)))
    walk(wrapper, "")
    return facts


def tree_changes(before: bytes, after: bytes) -> tuple[list[tuple[str, str, str]], list[tuple[str, str, str]]]:
    old, new = tree_facts(before), tree_facts(after)
    return sorted((old - new).elements()), sorted((new - old).elements())
