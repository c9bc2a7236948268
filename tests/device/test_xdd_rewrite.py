"""The regenerated XDD written over the file it came from (issue 34): unedited it is the file, byte for byte; after
one edit only that value differs in the XML tree, written where the file holds it (an object attribute, or the
parameter's ``defaultValue`` element in the object dictionary editors' layout), in the file's style. Over files of
both CiA 311 layouts, the XDD test files and hypothesis-generated files."""

from __future__ import annotations

import difflib
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from lxml import etree

from drivebench.device.formats.xdd import read_xdd
from drivebench.device.profiles.loader import LoadedFile
from drivebench.device.profiles.profile import Profile
from drivebench.services.profiles.edit import ObjectEdit, edited, regenerated_xdd
from tests.device.xdd_quirk_corpus import CASES
from tests.device.xdd_rewrite_corpus import (
    ATTRIBUTES,
    IEC,
    MARKUP,
    PARAMETERS,
    REWRITE_FILES,
    VARS,
    Var,
    attribute_xdd,
    parameter_xdd,
)
from tests.device.xml_trees import tree_changes

DATA_XDD = Path(__file__).parent.parent / "data" / "xdd"
ALL_FILES = REWRITE_FILES + [(n, c) for n, c in CASES if n.endswith(".xdd")] + [
    (p.name, p.read_bytes()) for p in sorted(DATA_XDD.iterdir())]


def regenerated(profile: Profile, content: bytes, name: str) -> bytes:
    return regenerated_xdd(LoadedFile(profile, [], content, Path(name).suffix))


def changed_lines(before: bytes, after: bytes) -> list[str]:
    """The lines that differ: the removed ones with '-', then the added ones with '+'."""
    old, new = before.decode().splitlines(), after.decode().splitlines()
    changed: list[str] = []
    for tag, i1, i2, j1, j2 in difflib.SequenceMatcher(None, old, new, autojunk=False).get_opcodes():
        if tag != "equal":
            changed += [f"-{line}" for line in old[i1:i2]] + [f"+{line}" for line in new[j1:j2]]
    return changed


def assert_one_value_changed(before: bytes, after: bytes, old: str, new: str) -> None:
    """One line differs, and in it only the value text (every other byte of the file is as it was)."""
    changed = changed_lines(before, after)
    assert len(changed) == 2 and changed[0][0] == "-" and changed[1][0] == "+", changed
    assert changed[0][1:].replace(f'"{old}"', f'"{new}"') == changed[1][1:], changed


@pytest.mark.parametrize(("name", "content"), ALL_FILES, ids=[n for n, _ in ALL_FILES])
def test_an_unedited_profile_regenerates_its_xdd_byte_for_byte(name: str, content: bytes) -> None:
    profile = read_xdd(content, source=name).profile
    assert regenerated(profile, content, name) == content


@pytest.mark.parametrize(("content", "place"), [
    (ATTRIBUTES, ("CANopenObject[index=2000]", "@defaultValue", "0x0BB8", "0x0DAC")),
    (PARAMETERS, ("parameter[uniqueID=UID_OBJ_2000]/{http://www.canopen.org/xml/1.1}defaultValue[1]", "@value",
                  "0x0BB8", "0x0DAC"))], ids=["attributes", "parameters"])
def test_one_edited_default_changes_only_that_value_where_the_file_holds_it(
        content: bytes, place: tuple[str, str, str, str]) -> None:
    profile = read_xdd(content, source="in.xdd").profile
    written = regenerated(edited(profile, 0x2000, 0, ObjectEdit(default=3500)), content, "in.xdd")
    gone, added = tree_changes(content, written)
    tail, attribute, old, new = place
    assert len(gone) == len(added) == 1, (gone, added)
    assert gone[0][0].endswith(tail) and gone[0][1:] == (attribute, old), gone
    assert added[0][0] == gone[0][0] and added[0][1:] == (attribute, new), added
    again = {(o.index, o.subindex): o for o in read_xdd(written, source="in.xdd").profile.objects}
    assert again[(0x2000, 0)].default == 3500
    assert_one_value_changed(content, written, "0x0BB8", "0x0DAC")
    assert written.startswith(content[:content.index(b"<ISO15745ProfileContainer")])  # declaration, comment kept


@pytest.mark.parametrize("content", [ATTRIBUTES, PARAMETERS], ids=["attributes", "parameters"])
@pytest.mark.parametrize(("index", "field", "value"), [
    (0x2000, "max", 9000), (0x2000, "min", 10), (0x2000, "min", None), (0x2001, "max", 100), (0x2001, "min", -100),
    (0x2000, "name", "Speed limit"), (0x2000, "description", "The speed limit"), (0x2000, "unit", "rpm"),
    (0x2000, "default", None), (0x2000, "denotation", "left axis"), (0x2000, "parameter_value", 1200),
    (0x2002, "default", 7)])
def test_each_field_of_an_edit_comes_back_and_nothing_else_changes(content: bytes, index: int, field: str,
                                                                   value: object) -> None:
    profile = read_xdd(content, source="in.xdd").profile
    changed = edited(profile, index, 0, ObjectEdit(**{field: value}))
    written = regenerated(changed, content, "in.xdd")
    again = read_xdd(written, source="in.xdd").profile
    assert again.model_dump(exclude={"id"}) == changed.model_dump(exclude={"id"})
    gone, added = tree_changes(content, written)
    touched = {path for path, _, _ in gone + added}
    assert touched and all(f"index={index:04X}" in path or f"UID_OBJ_{index:04X}" in path for path in touched), (
        gone, added)
    assert all(line.strip() for line in changed_lines(content, written))  # no blank line left or added


@pytest.mark.parametrize("content", [ATTRIBUTES, PARAMETERS], ids=["attributes", "parameters"])
def test_added_and_removed_objects_in_the_files_style(content: bytes) -> None:
    profile = read_xdd(content, source="in.xdd").profile
    extra = next(o for o in profile.objects if o.index == 0x2001).model_copy(
        update={"index": 0x2FFF, "name": "Added", "xdd_unique_id": None})
    fewer = [o for o in profile.objects if o.index != 0x2001]
    for objects in ([*profile.objects, extra], fewer):
        changed = profile.model_copy(update={"objects": objects})
        written = regenerated(changed, content, "in.xdd")
        again = read_xdd(written, source="in.xdd")
        assert again.profile.model_dump(exclude={"id"}) == changed.model_dump(exclude={"id"})
        assert [w.message for w in again.warnings] == [w.message for w in read_xdd(content, source="in.xdd").warnings]
        namespace = etree.QName(etree.fromstring(content)).namespace
        tags = {etree.QName(e).namespace for e in etree.fromstring(written).iter("{*}CANopenObject")}
        assert tags == {namespace}
        changed = changed_lines(content, written)  # lines added or taken out, no other line touched
        assert changed and {line[0] for line in changed} == ({"+"} if objects is not fewer else {"-"}), changed
        if content is PARAMETERS:  # the values on the parameter, as the file keeps them
            assert b'<CANopenObject index="2FFF" name="Added" objectType="7" PDOmapping="optional"' in written \
                or objects is fewer
            assert (b'UID_OBJ_2001"' in written) is (objects is not fewer)


# --- hypothesis: generated files of both layouts ----------------------------------------------------------
RANGES = {0x0005: (0, 0xFF), 0x0006: (0, 0xFFFF), 0x0007: (0, 0xFFFFFFFF), 0x0002: (-128, 127),
          0x0003: (-32768, 32767), 0x0004: (-(1 << 31), (1 << 31) - 1)}


@st.composite
def xdd_files(draw: st.DrawFn) -> tuple[bytes, list[tuple[int, int, int]]]:
    """An XDD of either layout with random VAR objects (type, default in decimal or hex of any digit count and
    case), line ends; and (index, type, default) of each."""
    count = draw(st.integers(1, 5))
    variables, facts = [], []
    for n in range(count):
        code = draw(st.sampled_from(sorted(IEC)))
        low, high = RANGES[code]
        value = draw(st.integers(max(low, 0) if draw(st.booleans()) else low, high))
        text = str(value)
        if value >= 0 and draw(st.booleans()):
            digits = f"{value:0{draw(st.integers(1, 8))}X}"
            text = "0x" + (digits.lower() if draw(st.booleans()) else digits)
        variables.append(Var(0x2000 + n, code, text))
        facts.append((0x2000 + n, code, value))
    build = draw(st.sampled_from([attribute_xdd, parameter_xdd]))
    return build(variables, newline=draw(st.sampled_from(["\n", "\r\n"]))), facts


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(xdd_files(), st.data())
def test_generated_files_regenerate_unchanged_and_one_edit_changes_one_value(
        generated: tuple[bytes, list[tuple[int, int, int]]], data: st.DataObject) -> None:
    content, objects = generated
    profile = read_xdd(content, source="generated.xdd").profile
    assert regenerated(profile, content, "generated.xdd") == content
    index, code, value = data.draw(st.sampled_from(objects))
    low, high = RANGES[code]
    new = data.draw(st.integers(low, high).filter(lambda v: v != value))
    written = regenerated(edited(profile, index, 0, ObjectEdit(default=new)), content, "generated.xdd")
    gone, added = tree_changes(content, written)
    assert len(gone) == len(added) == 1 and gone[0][0] == added[0][0] and gone[0][1] == added[0][1], (gone, added)
    assert f"{index:04X}" in gone[0][0]
    assert len(changed_lines(content, written)) == 2
    again = read_xdd(written, source="generated.xdd").profile.objects
    assert next(o.default for o in again if (o.index, o.subindex) == (index, 0)) == new


def test_a_value_in_a_start_tag_over_two_lines_changes_on_its_line() -> None:
    profile = read_xdd(ATTRIBUTES, source="in.xdd").profile
    written = regenerated(edited(profile, 0x1000, 0, ObjectEdit(default=0x00040191)), ATTRIBUTES, "in.xdd")
    assert_one_value_changed(ATTRIBUTES, written, "0x00030191", "0x00040191")


@pytest.mark.parametrize(("index", "old", "new", "value"), [(0x2001, "-5", "-6", -6),
                                                        (0x2000, "0x0BB8", "0x0DAC", 3500)])
def test_markup_around_an_edit_keeps_its_bytes(index: int, old: str, new: str, value: int) -> None:
    profile = read_xdd(MARKUP, source="in.xdd").profile
    written = regenerated(edited(profile, index, 0, ObjectEdit(default=value)), MARKUP, "in.xdd")
    changed = changed_lines(MARKUP, written)
    assert len(changed) == 2 and changed[0][1:].replace(f"'{old}'", f"'{new}'").replace(
        f'"{old}"', f'"{new}"') == changed[1][1:], changed
    assert b"<?tool keep?>" in written and b"<![CDATA[CiA 401 <device>]]>" in written


@pytest.mark.parametrize(("encoding", "bom", "declared"), [
    ("utf-16-le", b"\xff\xfe", "UTF-16"), ("utf-16-be", b"", "UTF-16"), ("latin-1", b"", "ISO-8859-1"),
    ("utf-8", b"\xef\xbb\xbf", "utf-8")])
def test_an_edit_keeps_the_files_encoding_and_bom(encoding: str, bom: bytes, declared: str) -> None:
    text = ATTRIBUTES.decode().replace('encoding="utf-8"', f'encoding="{declared}"').replace("Example IO", "Müller IO")
    content = bom + text.encode(encoding)
    profile = read_xdd(content, source="wide.xdd").profile
    assert regenerated(profile, content, "wide.xdd") == content
    written = regenerated(edited(profile, 0x2000, 0, ObjectEdit(default=3500)), content, "wide.xdd")
    assert written.startswith(bom)
    assert_one_value_changed(text.encode(), written[len(bom):].decode(encoding).encode(), "0x0BB8", "0x0DAC")


def test_limits_removed_take_their_range_along_and_new_elements_get_their_own_lines() -> None:
    profile = read_xdd(PARAMETERS, source="in.xdd").profile
    written = regenerated(edited(profile, 0x2000, 0, ObjectEdit(min=None, max=None)), PARAMETERS, "in.xdd")
    assert {line[0] for line in changed_lines(PARAMETERS, written)} == {"-"}
    assert b"allowedValues" not in written.split(b'UID_OBJ_2000"', 1)[1].split(b"</q1:parameter>", 1)[0]
    written = regenerated(edited(profile, 0x2001, 0, ObjectEdit(max=100)), PARAMETERS, "in.xdd")
    assert [line[0] + line[1:].strip() for line in changed_lines(PARAMETERS, written)] == [
        "+<q1:allowedValues>", "+<q1:range>", '+<q1:maxValue value="100" />', "+</q1:range>", "+</q1:allowedValues>"]


def test_the_fixed_files_hold_what_they_say() -> None:
    assert [v.index for v in VARS] == [0x2000, 0x2001, 0x2002]
    for content in (ATTRIBUTES, PARAMETERS):
        objects = {(o.index, o.subindex): o for o in read_xdd(content, source="in.xdd").profile.objects}
        assert objects[(0x2000, 0)].default == 3000 and objects[(0x2000, 0)].max == 8000
        assert objects[(0x2001, 0)].default == -5 and objects[(0x1018, 1)].default in (0x4D2, 0)
