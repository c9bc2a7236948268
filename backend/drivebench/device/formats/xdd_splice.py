"""An edited XML tree written into the text it was read from: every node nobody changed keeps its bytes (its
attribute order, quotes, spacing, line breaks inside the tag, ``<x />``, ``<x></x>``, character references), a
changed start tag has only its changed attributes rewritten, and only new nodes are written anew (in the file's
empty-tag style). The text's tags are matched to the tree's nodes in document order; where they do not match (an
XML form this scanner does not know) the caller serializes the whole tree instead."""

from __future__ import annotations

import re
from dataclasses import dataclass

from lxml import etree

_TOKEN = re.compile(
    r"<!--.*?-->|<\?.*?\?>|<!\[CDATA\[.*?\]\]>|</[^>]*>"
    r"|<[^\s/>!?][^\s/>]*(?:\s+[^\s=/>]+\s*=\s*(?:\"[^\"]*\"|'[^']*'))*\s*/?>", re.DOTALL)
_ATTRIBUTE = r"(\s+){name}(\s*=\s*)(\"[^\"]*\"|'[^']*')"


@dataclass
class _Span:
    start: int
    tag_end: int
    """Where the start tag (or the comment/PI) ends."""
    close: int = -1
    """Where the end tag starts (-1: a self-closing tag, a comment or a PI)."""
    end: int = -1


@dataclass
class _State:
    attributes: list[tuple[str, str]]
    text: str | None
    tail: str | None
    children: list[etree._Element]


class Snapshot:
    """Each node of a tree as it was read: its attributes, text, tail and children (taken before any edit)."""

    def __init__(self, root: etree._Element) -> None:
        self.root = root
        self.nodes = list(root.iter())
        self.states = {node: _State([(str(k), str(v)) for k, v in node.attrib.items()]
                                    if isinstance(node.tag, str) else [], node.text, node.tail, list(node))
                       for node in self.nodes}


def _spans(text: str, start: int, nodes: list[etree._Element]) -> dict[etree._Element, _Span] | None:
    """Each node's place in ``text`` (the root's start tag at ``start``), or None where the tags do not match."""
    spans: dict[etree._Element, _Span] = {}
    stack: list[_Span] = []
    at = 0
    for found in _TOKEN.finditer(text, start):
        token = found.group()
        if token.startswith("<![CDATA["):
            continue
        if token.startswith("</"):
            if not stack:
                return None
            span = stack.pop()
            span.close, span.end = found.start(), found.end()
            if not stack:
                break
            continue
        if at >= len(nodes):
            return None
        node = nodes[at]
        at += 1
        is_element = isinstance(node.tag, str)
        kind_matches = (token.startswith("<!--") and isinstance(node, etree._Comment)) or (
            token.startswith("<?") and isinstance(node, etree._ProcessingInstruction)) or (
            is_element and not token.startswith(("<!--", "<?")))
        if not kind_matches:
            return None
        span = _Span(found.start(), found.end())
        spans[node] = span
        if is_element and not token.endswith("/>"):
            stack.append(span)
        else:
            span.end = span.tag_end
    return spans if at == len(nodes) and not stack else None


def _escape(text: str, *, quote: str = "") -> str:
    escaped = text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")
    if quote:
        escaped = escaped.replace(quote, "&quot;" if quote == '"' else "&apos;").replace("\n", "&#10;").replace(
            "\r", "&#13;").replace("\t", "&#9;")
    return escaped


class _Writer:
    def __init__(self, text: str, snapshot: Snapshot, spans: dict[etree._Element, _Span]) -> None:
        self.text = text
        self.snapshot = snapshot
        self.spans = spans
        self.empty_end = " />" if text.count(" />") > text.count("/>") - text.count(" />") else "/>"
        self.newline = "\r\n" if "\r\n" in text else "\n"
        self.chosen: dict[etree._Element, str | None] = {}
        """The prefix written for each new node."""

    def fresh(self, text: str | None) -> str:
        """Text the file did not have, escaped, with the file's line ends (the parser gave them as LF)."""
        escaped = _escape(text or "")
        return escaped.replace("\n", self.newline) if self.newline != "\n" else escaped

    def node(self, node: etree._Element) -> tuple[str, bool]:
        """The text of ``node`` and whether it is as read (its whole subtree)."""
        span = self.spans.get(node)
        if span is None:
            return self.new(node), False
        if not isinstance(node.tag, str):
            return self.text[span.start:span.end], True
        state = self.snapshot.states[node]
        attributes = [(str(k), str(v)) for k, v in node.attrib.items()]
        children = list(node)
        parts = [self.own_text(node, span, state)]
        same = attributes == state.attributes and children == state.children and node.text == state.text
        for child in children:
            written, kept = self.node(child)
            tail = self.tail(child)
            same = same and kept and child.tail == self.snapshot.states[child].tail
            parts += [written, tail]
        if same:
            return self.text[span.start:span.end], True
        start_tag = self.text[span.start:span.tag_end]
        if attributes != state.attributes:
            start_tag = self.start_tag(start_tag, dict(state.attributes), attributes)
        content = "".join(parts)
        if span.close < 0:  # was <x ... />
            if not content:
                return start_tag, False
            opened = re.sub(r"\s*/>$", ">", start_tag)
            return f"{opened}{content}</{self.qname(node)}>", False
        return start_tag + content + self.text[span.close:span.end], False

    def own_text(self, node: etree._Element, span: _Span, state: _State) -> str:
        if node.text == state.text and span.close >= 0:
            first = next((self.spans[c].start for c in state.children if c in self.spans), span.close)
            return self.text[span.tag_end:first]
        return self.fresh(node.text)

    def tail(self, child: etree._Element) -> str:
        span = self.spans.get(child)
        state = self.snapshot.states.get(child)
        if span is None or state is None or child.tail != state.tail:
            return self.fresh(child.tail)
        parent = child.getparent()
        siblings = self.snapshot.states[parent].children if parent is not None else []
        at = siblings.index(child) if child in siblings else -1
        following = siblings[at + 1] if 0 <= at < len(siblings) - 1 else None
        parent_span = self.spans.get(parent) if parent is not None else None
        stop = self.spans[following].start if following is not None else (
            parent_span.close if parent_span is not None else -1)
        return self.text[span.end:stop] if stop >= span.end else self.fresh(child.tail)

    def start_tag(self, tag: str, old: dict[str, str], attributes: list[tuple[str, str]]) -> str:
        """``tag`` with the attributes that changed rewritten, removed ones out, new ones after the last."""
        quote = next((m.group(1) for m in re.finditer(r"=\s*([\"'])", tag)), '"')
        new = dict(attributes)
        for name in old:
            if "}" in name:
                continue  # a namespaced attribute (xsi:type) is not one an edit changes
            pattern = re.compile(_ATTRIBUTE.format(name=re.escape(name)))
            if name not in new:
                tag = pattern.sub("", tag, count=1)
            elif new[name] != old[name] and (found := pattern.search(tag)) is not None:
                own = found.group(3)[0]  # the attribute's own quote
                value = f"{own}{_escape(new[name], quote=own)}{own}"
                tag = tag[:found.start(3)] + value + tag[found.end(3):]
        added = "".join(f" {name}={quote}{_escape(value, quote=quote)}{quote}" for name, value in attributes
                        if name not in old and "}" not in name)
        end = re.search(r"\s*/?>$", tag)
        at = end.start() if end is not None else len(tag)
        return tag[:at] + added + tag[at:]

    def qname(self, node: etree._Element) -> str:
        name = etree.QName(node).localname
        prefix = self.chosen.get(node, node.prefix)
        return f"{prefix}:{name}" if prefix else name

    def choose_prefix(self, node: etree._Element) -> None:
        """A new node's prefix as its parent writes the same namespace (a file that maps its namespace both to
        the default and to ``q1:`` keeps the form the parent has)."""
        parent = node.getparent()
        namespace = etree.QName(node).namespace
        if parent is None or etree.QName(parent).namespace != namespace:
            return
        prefix = self.chosen.get(parent, parent.prefix)
        if node.nsmap.get(prefix) == namespace:
            self.chosen[node] = prefix

    def new(self, node: etree._Element) -> str:
        """A node the file did not have, written in its style (its namespace declarations where its parent's
        differ)."""
        if isinstance(node, etree._Comment):
            return f"<!--{node.text or ''}-->"
        if not isinstance(node.tag, str):
            return etree.tostring(node, encoding="unicode", with_tail=False)
        parent = node.getparent()
        self.choose_prefix(node)
        inherited = parent.nsmap if parent is not None else {}
        declarations = "".join(f' xmlns{":" + p if p else ""}="{u}"' for p, u in node.nsmap.items()
                               if inherited.get(p) != u)
        if node.prefix is None and etree.QName(node).namespace is None and inherited.get(None):
            declarations += ' xmlns=""'
        attributes = "".join(f' {_attribute_name(node, k)}="{_escape(str(v), quote=chr(34))}"'
                             for k, v in node.attrib.items())
        content = self.fresh(node.text) + "".join(self.node(child)[0] + self.fresh(child.tail) for child in node)
        head = f"<{self.qname(node)}{declarations}{attributes}"
        return f"{head}>{content}</{self.qname(node)}>" if content else f"{head}{self.empty_end}"


def _attribute_name(node: etree._Element, name: str) -> str:
    qualified = etree.QName(name)
    if qualified.namespace is None:
        return name
    prefix = next((p for p, u in node.nsmap.items() if u == qualified.namespace and p), None)
    return f"{prefix}:{qualified.localname}" if prefix else qualified.localname


def spliced(text: str, start: int, root: etree._Element, snapshot: Snapshot) -> tuple[str, int] | None:
    """The root element as text written over ``text`` (it starts at ``start``) and where its original ended; None
    where the text's tags do not match the tree as read."""
    spans = _spans(text, start, snapshot.nodes)
    if spans is None or root not in spans:
        return None
    return _Writer(text, snapshot, spans).node(root)[0], spans[root].end
