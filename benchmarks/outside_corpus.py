"""Regenerated exports of an outside corpus (issue 34): real vendor EDS/DCF/XDD files from public repositories,
each through the real app. Prints the figures and puts them into the ``## Outside corpus`` section of
``benchmarks/RESULTS.md``.

For each file: the upload (``POST /api/profiles``); (a) an EDS/DCF regenerated unedited
(``GET /api/profiles/{id}/eds?regenerate=true``) equals the upload byte for byte; (b) one default of a rw VAR edited
(``PATCH /api/profiles/{id}/objects/{index}/{sub}``) changes only that key's line; (c) EDS -> XDD -> upload -> EDS:
the sections and keys the round trip loses or changes, by kind; (d) XDD -> XDD: the elements and attributes the
regenerated XDD loses, and whether the profile read back from it is the same; (e) one default of an XDD edited
(the same PATCH) changes only that value's attribute in the regenerated XDD.

The files are not ours (their licences are their authors'): they stay outside the repository.

    .venv/bin/python benchmarks/outside_corpus.py /tmp/outside-corpus
"""

from __future__ import annotations

import contextlib
import re
import struct
import sys
import tempfile
import time
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from fastapi.testclient import TestClient
from lxml import etree

from drivebench.config import REPO_ROOT, settings
from drivebench.device.formats.eds_ini import decode_text, parse_ini
from drivebench.device.formats.eds_quirks import parse_int_strict
from drivebench.web.app import create_app

RESULTS = REPO_ROOT / "benchmarks" / "RESULTS.md"
EDS_SUFFIXES = (".eds", ".dcf")
XML_SUFFIXES = (".xdd", ".xdc")
OBJECT_LISTS = ("MANDATORYOBJECTS", "OPTIONALOBJECTS", "MANUFACTUREROBJECTS")
OBJECT_SECTION = re.compile(r"^[0-9A-F]{4}(sub[0-9A-F]+)?$", re.IGNORECASE)


@dataclass
class Outcome:
    name: str
    accepted: bool = False
    refusal: str = ""
    identical: bool | None = None
    edit_clean: bool | None = None
    edit_note: str = ""
    export_note: str = ""
    lost: Counter[str] = field(default_factory=Counter)
    changed: Counter[str] = field(default_factory=Counter)
    kept_expanded: Counter[str] = field(default_factory=Counter)
    added: Counter[str] = field(default_factory=Counter)
    xdd_profile_same: bool | None = None
    xdd_edit_clean: bool | None = None
    xml_facts: int = 0
    """Elements and attributes (each with its value) of an uploaded XDD."""
    xml_facts_lost: int = 0
    """Of those, the ones the XDD written again does not have (layout and data alike)."""


def kind_of(section: str, key: str) -> str:
    """``[2000sub1] DefaultValue`` -> ``object DefaultValue``; ``[DeviceInfo] Granularity`` -> itself."""
    if OBJECT_SECTION.match(section):
        return f"object {key}"
    compact = re.match(r"^[0-9A-F]{4}(VALUE|NAME|DENOTATION)$", section, re.IGNORECASE)
    if compact:
        return f"[xxxx{compact.group(1).capitalize()}] {'NrOfEntries' if key == 'nrofentries' else 'n='}"
    if re.match(r"^M\d+", section):
        return f"[M..] {key}"
    return f"[{section}] {key}"


def ini_keys(content: bytes, name: str) -> dict[tuple[str, str], str]:
    sections = parse_ini(decode_text(content, name), name)
    return {(s.upper() if OBJECT_SECTION.match(s) else s, k.lower()): key.value.strip()
            for s, section in sections.items() for k, key in section.keys.items()}


def changed_lines(before: bytes, after: bytes) -> list[tuple[str, str]]:
    """(section, line) of each line of ``before`` that ``after`` does not have at the same place, and the other
    way round (the files are compared line by line: a regenerated file keeps every line's position)."""
    old, new = before.decode("latin-1").splitlines(), after.decode("latin-1").splitlines()
    out: list[tuple[str, str]] = []
    section = ""
    for number in range(max(len(old), len(new))):
        a = old[number] if number < len(old) else None
        b = new[number] if number < len(new) else None
        if a is not None and a.strip().startswith("["):
            section = a.strip()[1:].split("]")[0]
        if a != b:
            out.append((section, a if a is not None else f"(added) {b}"))
    return out


def editable(profile: dict[str, Any]) -> dict[str, Any] | None:
    """A rw VAR with an integer default the model holds as a number (no formula, no kept text)."""
    for entry in profile["objects"]:
        default = entry.get("default")
        if (entry.get("access") == "rw" and entry.get("object_type") == "VAR" and isinstance(default, int)
                and not isinstance(default, bool) and not entry.get("default_expr")
                and not (entry.get("value_texts") or {}).get("DefaultValue") and entry.get("factor", 1) == 1):
            return entry
    return None


def check_edit(client: TestClient, profile_id: str, profile: dict[str, Any], content: bytes, out: Outcome) -> None:
    entry = editable(profile)
    if entry is None:
        out.edit_note = "no rw VAR with a numeric default"
        return
    index, sub = int(str(entry["index"]), 16) if isinstance(entry["index"], str) else entry["index"], \
        entry["subindex"]
    value = entry["default"] + 1 if entry.get("max") is None or entry["default"] + 1 <= entry["max"] else \
        entry["default"] - 1
    response = client.patch(f"/api/profiles/{profile_id}/objects/0x{index:04X}/{sub}", json={"default": value})
    if response.status_code != 200:
        out.edit_clean, out.edit_note = False, f"PATCH {response.status_code}: {response.json().get('detail')}"
        return
    after = client.get(f"/api/profiles/{profile_id}/eds", params={"regenerate": "true"}).content
    differing = changed_lines(content, after)
    ok = len(differing) == 1 and differing[0][0].upper() in (f"{index:04X}", f"{index:04X}SUB{sub:X}") and \
        differing[0][1].split("=")[0].strip().lower() == "defaultvalue"
    out.edit_clean = ok
    if not ok:
        out.edit_note = f"0x{index:04X}/{sub}: {len(differing)} lines differ, first {differing[:2]}"


def upload(client: TestClient, name: str, content: bytes) -> tuple[str | None, dict[str, Any] | str]:
    response = client.post("/api/profiles", files={"file": (name, content)})
    if response.status_code != 201:
        return None, f"{response.status_code}: {response.json().get('detail', response.text)[:160]}"
    profile_id = str(response.json()["id"])
    return profile_id, client.get(f"/api/profiles/{profile_id}").json()


def accepted(client: TestClient, path: Path, out: Outcome) -> tuple[str, dict[str, Any], bytes] | None:
    """Upload the file as it is; the profile id, the profile and the bytes, or None (the refusal noted)."""
    content = path.read_bytes()
    profile_id, profile = upload(client, path.name, content)
    if profile_id is None:
        out.refusal = str(profile)
        return None
    out.accepted = True
    assert isinstance(profile, dict)
    return profile_id, profile, content


def check_eds(client: TestClient, path: Path, out: Outcome) -> None:
    if (uploaded := accepted(client, path, out)) is None:
        return
    profile_id, profile, content = uploaded
    regenerated = client.get(f"/api/profiles/{profile_id}/eds", params={"regenerate": "true"})
    out.identical = regenerated.status_code == 200 and regenerated.content == content
    if regenerated.status_code != 200:
        out.export_note = f"{regenerated.status_code}: {regenerated.json().get('detail')}"[:200]
    xdd = client.get(f"/api/profiles/{profile_id}/xdd").content
    xdd_id, _ = upload(client, f"{path.stem}-roundtrip.xdd", xdd)
    original = ini_keys(content, path.name)
    if xdd_id is None:
        out.lost["(the XDD written from it was refused)"] += 1
    else:
        written_back = client.get(f"/api/profiles/{xdd_id}/eds", params={"regenerate": "true"})
        if written_back.status_code != 200:
            out.lost["(the EDS written from the uploaded XDD was refused)"] += 1
            client.delete(f"/api/profiles/{xdd_id}")
            check_edit(client, profile_id, profile, content, out)
            return
        back = ini_keys(written_back.content, "b.eds")
        compare_lists(original, back, out)
        for where, value in original.items():
            if where[0] in OBJECT_LISTS:
                continue
            if where not in back:
                kept = expanded(original, back, where, value)
                if kept:
                    out.kept_expanded[kind_of(*where)] += 1
                else:
                    out.lost[kind_of(*where)] += 1
            elif not same_value(value, back[where]):
                out.changed[kind_of(*where)] += 1
        client.delete(f"/api/profiles/{xdd_id}")
    check_edit(client, profile_id, profile, content, out)
    client.delete(f"/api/profiles/{profile_id}")


def compare_lists(original: dict[tuple[str, str], str], back: dict[tuple[str, str], str], out: Outcome) -> None:
    """Objects listed in another object list than the file's (XDD has no object lists: the EDS written from one
    lists each object by its CiA 306 index range), and objects the export added (the CiA 301 mandatory ones)."""
    def listed(keys: dict[tuple[str, str], str]) -> dict[int, str]:
        found = {}
        for (section, key), value in keys.items():
            if section in OBJECT_LISTS and key != "supportedobjects":
                with contextlib.suppress(ValueError):
                    found[int(value.split(";")[0].strip(), 0)] = section
        return found
    before, after = listed(original), listed(back)
    for index, section in before.items():
        if index not in after:
            out.lost["object list entry"] += 1
        elif after[index] != section:
            out.changed[f"object listed in [{after[index]}], not [{section}]"] += 1
    out.added["object the export added to the lists"] += len(set(after) - set(before))


def expanded(original: dict[tuple[str, str], str], back: dict[tuple[str, str], str], where: tuple[str, str],
             value: str) -> bool:
    """Whether a key of a compact ARRAY (``CompactSubObj``, ``[1003Value]`` ...) is in the expanded sub-objects of
    the regenerated file (CiA 311 has no compact form: the XDD lists each sub-object)."""
    section, key = where
    index = section[:4]
    if section.endswith(("VALUE", "NAME", "DENOTATION")) and key.isdigit():
        field_name = {"VALUE": "parametervalue", "NAME": "parametername", "DENOTATION": "denotation"}[
            next(s for s in ("VALUE", "NAME", "DENOTATION") if section.endswith(s))]
        got = back.get((f"{index}SUB{int(key):X}", field_name))
        return got is not None and same_value(value, got)
    if key == "nrofentries":
        return True
    if (section, "compactsubobj") not in original:
        return False
    if key == "compactsubobj":
        return same_value(value, back.get((f"{index}SUB0", "defaultvalue"), ""))
    got = back.get((f"{index}SUB1", key))
    return got is not None and same_value(value, got)


def same_value(a: str, b: str) -> bool:
    """Equal as text, or as CiA 306 numbers (``0x0007`` == ``7``, ``001`` == ``0x00000001``), or as text without a
    trailing comment."""
    a, b = a.split(";")[0].strip(), b.split(";")[0].strip()
    if a.lower() == b.lower():
        return True
    try:
        return parse_int_strict(a) == parse_int_strict(b)
    except ValueError:
        pass
    try:
        return float(a) == float(b)
    except ValueError:
        pass
    for hex_text, other in ((a, b), (b, a)):  # a REAL written as its bit pattern (0x40490FDB) and as a number
        digits = hex_text.lower().removeprefix("0x")
        if hex_text.lower().startswith("0x") and len(digits) in (8, 16):
            with contextlib.suppress(ValueError):
                number = struct.unpack(">f" if len(digits) == 8 else ">d", bytes.fromhex(digits))[0]
                return number == float(other)
    return False


def xml_facts(content: bytes) -> Counter[str]:
    """Each element's attributes as ``tag@name=value`` (namespaces dropped), counted."""
    facts: Counter[str] = Counter()
    root = etree.fromstring(content, etree.XMLParser(resolve_entities=False, no_network=True, huge_tree=True))
    for element in root.iter():
        if not isinstance(element.tag, str):
            continue
        tag = etree.QName(element).localname
        facts[f"<{tag}>"] += 1
        for name, value in element.attrib.items():
            facts[f"{tag}@{etree.QName(name).localname}={value.strip()}"] += 1
    return facts


def check_xdd_edit(client: TestClient, profile_id: str, profile: dict[str, Any], content: bytes,
                   out: Outcome) -> None:
    """One default edited: the regenerated XDD differs from the upload in one attribute (the value's)."""
    entry = editable(profile)
    if entry is None:
        out.edit_note = "no rw VAR with a numeric default"
        return
    index = int(str(entry["index"]), 16) if isinstance(entry["index"], str) else entry["index"]
    value = entry["default"] + 1 if entry.get("max") is None or entry["default"] + 1 <= entry["max"] else \
        entry["default"] - 1
    response = client.patch(f"/api/profiles/{profile_id}/objects/0x{index:04X}/{entry['subindex']}",
                            json={"default": value})
    if response.status_code != 200:
        out.xdd_edit_clean, out.edit_note = False, f"PATCH {response.status_code}: {response.json().get('detail')}"
        return
    after = client.get(f"/api/profiles/{profile_id}/xdd", params={"regenerate": "true"}).content
    gone, added = xml_facts(content) - xml_facts(after), xml_facts(after) - xml_facts(content)
    out.xdd_edit_clean = gone.total() == added.total() == 1 and next(iter(gone)).split("=")[0] == next(
        iter(added)).split("=")[0]
    if not out.xdd_edit_clean:
        out.edit_note = f"0x{index:04X}/{entry['subindex']}: lost {list(gone)[:3]}, added {list(added)[:3]}"


def check_xdd(client: TestClient, path: Path, out: Outcome) -> None:
    if (uploaded := accepted(client, path, out)) is None:
        return
    profile_id, profile, content = uploaded
    written = client.get(f"/api/profiles/{profile_id}/xdd", params={"regenerate": "true"}).content
    out.identical = written == content
    before, after = xml_facts(content), xml_facts(written)
    out.xml_facts, out.xml_facts_lost = before.total(), (before - after).total()
    for fact, count in (before - after).items():
        out.lost[fact.split("=")[0]] += count
    again_id, again = upload(client, f"{path.stem}-again.xdd", written)
    if again_id is None:
        out.lost["(the regenerated XDD was refused)"] += 1
    else:
        assert isinstance(again, dict)
        out.xdd_profile_same = strip_ids(again) == strip_ids(profile)
        client.delete(f"/api/profiles/{again_id}")
    check_xdd_edit(client, profile_id, profile, content, out)
    client.delete(f"/api/profiles/{profile_id}")


def strip_ids(profile: dict[str, Any]) -> list[Any]:
    return [{k: v for k, v in entry.items() if k not in ("source_line",)} for entry in profile["objects"]]


def run(folder: Path) -> list[Outcome]:
    files = sorted(p for p in folder.rglob("*") if p.suffix.lower() in EDS_SUFFIXES + XML_SUFFIXES)
    outcomes = []
    with tempfile.TemporaryDirectory() as scratch:
        settings.user_profiles_dir = Path(scratch) / "user-profiles"
        with TestClient(create_app(), base_url="http://127.0.0.1") as client:
            for path in files:
                out = Outcome(str(path.relative_to(folder)))
                try:
                    (check_eds if path.suffix.lower() in EDS_SUFFIXES else check_xdd)(client, path, out)
                except Exception as exc:  # a benchmark lists what broke and goes on
                    out.refusal = out.refusal or f"error: {type(exc).__name__}: {exc}"[:200]
                outcomes.append(out)
    return outcomes


def table(outcomes: list[Outcome]) -> list[str]:
    eds = [o for o in outcomes if o.name.lower().endswith(EDS_SUFFIXES)]
    xml = [o for o in outcomes if o.name.lower().endswith(XML_SUFFIXES)]

    def count(items: list[Outcome], test: Any) -> int:
        return sum(1 for o in items if test(o))

    lines = ["| Figure | EDS/DCF | XDD/XDC |", "|---|---|---|",
             f"| files | {len(eds)} | {len(xml)} |",
             f"| accepted | {count(eds, lambda o: o.accepted)} | {count(xml, lambda o: o.accepted)} |",
             f"| regenerated unedited, byte-identical | {count(eds, lambda o: o.identical)} | "
             f"{count(xml, lambda o: o.identical)} |",
             f"| one-key edits clean (of files with an editable rw VAR) | {count(eds, lambda o: o.edit_clean)} of "
             f"{count(eds, lambda o: o.edit_clean is not None)} | {count(xml, lambda o: o.xdd_edit_clean)} of "
             f"{count(xml, lambda o: o.xdd_edit_clean is not None)} |",
             f"| EDS -> XDD -> EDS without a lost or changed key | "
             f"{count(eds, lambda o: o.accepted and not o.lost and not o.changed)} | - |",
             f"| XDD -> XDD: the profile read back is the same | - | {count(xml, lambda o: o.xdd_profile_same)} |",
             f"| XDD -> XDD: elements and attributes (with value) of the upload not in the export | - | "
             f"{sum(o.xml_facts_lost for o in xml)} of {sum(o.xml_facts for o in xml)} |"]
    lost: Counter[str] = Counter()
    changed: Counter[str] = Counter()
    files_lost: Counter[str] = Counter()
    for o in eds:
        lost.update(o.lost)
        changed.update(o.changed)
        files_lost.update(o.lost.keys())
    lines += ["", "EDS -> XDD -> EDS, keys lost (key: count in files):", ""]
    lines += [f"- `{kind}`: {n} in {files_lost[kind]} files" for kind, n in lost.most_common()] or ["- none"]
    lines += ["", "EDS -> XDD -> EDS, keys kept with another value:", ""]
    lines += [f"- `{kind}`: {n}" for kind, n in changed.most_common()] or ["- none"]
    kept: Counter[str] = Counter()
    added: Counter[str] = Counter()
    for o in eds:
        kept.update(o.kept_expanded)
        added.update(o.added)
    lines += ["", "EDS -> XDD -> EDS, keys of compact ARRAYs kept in the expanded sub-objects (CiA 311 has no "
              "compact form):", ""]
    lines += [f"- `{kind}`: {n}" for kind, n in kept.most_common()] or ["- none"]
    lines += ["", "EDS -> XDD -> EDS, added:", ""]
    lines += [f"- {kind}: {n}" for kind, n in added.most_common()] or ["- none"]
    xml_lost: Counter[str] = Counter()
    for o in xml:
        xml_lost.update(o.lost)
    lines += ["", "XDD -> XDD, attributes/elements lost:", ""]
    lines += [f"- `{kind}`: {n}" for kind, n in xml_lost.most_common()] or ["- none"]
    notes = [f"- {o.name}: refused ({o.refusal})" for o in outcomes if not o.accepted]
    notes += [f"- {o.name}: not byte-identical" + (f" (the regenerated export was refused: {o.export_note})"
                                                    if o.export_note else "")
              for o in eds if o.accepted and not o.identical]
    notes += [f"- {o.name}: edit {o.edit_note}" for o in eds if o.edit_clean is False]
    notes += [f"- {o.name}: read back differently" for o in xml if o.xdd_profile_same is False]
    notes += [f"- {o.name}: edit {o.edit_note}" for o in xml if o.xdd_edit_clean is False]
    if notes:
        lines += ["", "By file:", "", *notes]
    return lines


FINDINGS = (
    "Findings. Earlier rounds (43 files transcribed by hand from public repositories through a code-search tool: "
    "lely-core, python-canopen, CanFestival, Victron/Sevcon, SysTec, Faulhaber, Schunk, Technosoft, HEIG-VD, "
    "ros_canopen, node-canopen, gocanopen, Animatics, CANopenNode's demoDevice.xdd) brought every EDS/DCF to "
    "byte-identical unedited exports and clean one-key edits, and fixed in EDS -> XDD -> EDS: sub-object "
    "ObjectType=0x09, objects listed off their index range, empty ProductName=/ModifiedBy=/ParameterName=, ISO dates, "
    "CompactSubObj=255, an ARRAY without sub-objects, and in XDD -> XDD the DeviceFunction, format attributes, empty "
    "vendorID/productID, the tool's own properties and uniqueIDs; XDD -> XDD lost layout (values as object "
    "attributes, no dataTypeList structs: 1,543 of demoDevice.xdd's 5,248 elements/attributes). The two "
    "CANopenEditorLB XML files are not CiA 311 (root <DeviceProfile>) and are refused in words. "
    "Fifth round (branch corpus5): the corpus is rebuilt by benchmarks/outside_corpus_fetch.py from the package "
    "registries (26 pinned releases: python-canopen 0.6.0-2.4.1, canopen-asyncio 2.4.1, canopen-lens 0.5.1 and "
    "pycangui 0.4.1 source distributions on PyPI, node-canopen 1.1.1-6.2.1 tarballs on npm; 36 files in them, 19 "
    "the same bytes as another) with the 43 hand-transcribed files beside them: 60 files, 17 new (python-canopen's "
    "test/sample.eds in 10 versions and examples/eds/e35.eds in 3, node-canopen's test/sample.eds and "
    "examples/example.eds, canopen-lens' sample_drive.eds, pycangui's demo.eds). The releases looked at of other "
    "registry packages about CANopen carry none "
    "(canopen-monitor, eds-utils, pyeds-editor, canopen-utils, objdictgen, uc2canopen, dryve-d1, durand, canscan, "
    "hermes-canopen-nodes, pycanopendevice; oze-canopen's sdist did not build here), nor does a Debian package. "
    "Before this "
    "round's fixes (main at a1b6cc8, the 60 files): 57 of 57 byte-identical, 43 of 43 edits clean, 50 of 57 "
    "EDS -> XDD -> EDS without a lost or changed key; lost: an object list entry of an object without a section "
    "(python-canopen's e35.eds 0x6505 in 3 versions, gocanopen's 0x2000: 4 in 4 files), Factor=ERROR and an empty "
    "Description= (python-canopen's sample.eds 0x3050 sub 2: 3 and 3 in 3 files). Both fixed: 57 of 57 without a "
    "lost or changed key. The benchmark now compares numbers by CiA 306 (VendorNumber=001 against the XDD's "
    "0x00000001 was counted as a change). The issue's 180 files stay out of reach: the registries hold few vendor "
    "files, and hand transcription costs a read per 16 kB. "
    "Same round (branch xddtree): an XDD regenerated from an uploaded XDD is written over the upload's XML tree "
    "(device/formats/xdd_rewrite.py): XDD -> XDD loses 0 of demoDevice.xdd's 5,248 elements/attributes (was 1,543; "
    "unedited it is the upload byte for byte) and one PATCHed default changes only that parameter's "
    "defaultValue@value, one line of the file. XDD -> EDS -> XDD (measured by hand, not in the table) reads back the "
    "same profile, but its XDD, written from an EDS, lacks 3,299 of the 5,248 facts (the parameterList layout, the "
    "dataTypeList, the parameters' uniqueIDs: an EDS has no place for them).")




def write(body: list[str], folder: Path) -> None:
    when = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    absent = "" if (folder / "INDEX.md").exists() else ", absent here"
    text = "\n".join(["## Outside corpus", "", f"Written by `benchmarks/outside_corpus.py` on {when}: real EDS/DCF/XDD "
                      "files nobody here wrote, from public repositories and package releases (kept outside this "
                      "repository; rebuilt by `benchmarks/outside_corpus_fetch.py`; their list with registry, "
                      "package, version, path and sha256, or repository, path and commit, is the corpus's "
                      f"`INDEX.md`{absent}), "
                      "each uploaded through the real app.", "", *body, "", FINDINGS, "", ""])
    current = RESULTS.read_text()
    pattern = re.compile(r"^## Outside corpus\n.*?(?=^## |\Z)", re.DOTALL | re.MULTILINE)
    RESULTS.write_text(pattern.sub(lambda _: text, current) if pattern.search(current)
                       else current.rstrip("\n") + "\n\n" + text)


def main(argv: list[str]) -> int:
    folder = Path(argv[1]) if len(argv) > 1 else Path("/tmp/outside-corpus")
    if not folder.is_dir():
        print(f"No outside corpus at {folder}: nothing measured (give the folder of vendor files as the argument).")
        return 0
    body = table(run(folder))
    print("\n".join(body))
    if "--no-write" not in argv:
        write(body, folder)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
