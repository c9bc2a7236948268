"""The quirk corpus (tests/device/quirk_corpus.py): every file is accepted with the warning its quirk calls for,
and what is exported from it reads back as the same profile; generated and mutated files never crash the import."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from drivebench.device.formats.eds import Section, decode_text, parse_ini, read_eds
from drivebench.device.formats.eds_export import export_eds
from drivebench.device.formats.eds_quirks import ImportWarning, Warnings, node_expr, read_int
from drivebench.device.formats.xdd import read_xdd
from drivebench.device.formats.xdd_export import export_xdd
from drivebench.errors import ProfileError
from tests.device.quirk_corpus import BASE, CASES, CORPUS_FILES, Case

CORPUS = CORPUS_FILES
DATA_EDS = Path(__file__).resolve().parents[1] / "data" / "eds"


def test_the_corpus_is_large_and_its_base_is_clean() -> None:
    assert len(CORPUS) >= 60
    assert read_eds(BASE, source="base.eds").warnings == []


@pytest.mark.parametrize(("name", "content", "case"), CORPUS, ids=[c[0] for c in CORPUS])
def test_corpus_file_is_accepted_with_the_warning_due(name: str, content: bytes, case: Case) -> None:
    imported = read_eds(content, source=name)
    texts = [w.text() for w in imported.warnings]
    if case.warns is None:
        assert texts == []
    else:
        hits = [w for w in imported.warnings if case.warns in w.message]
        assert hits, texts
        assert hits[0].file == name and hits[0].line is not None and hits[0].line > 0
    assert len(imported.profile.objects) >= 10


KEPT_AS_WRITTEN = {"defaultvalue", "lowlimit", "highlimit", "parametervalue", "lowlimit/highlimit", "datatype",
                   "subnumber", "factor"}
"""Value keys an export writes as the file had them where the import read them with a change (issue 34): their
re-import gives the same reading again (``SubNumber`` of a DCF that lists some of the sub-objects, a ``Factor`` no
number can be read from)."""


def not_of_kept_texts(warnings: list[ImportWarning]) -> list[ImportWarning]:
    """The warnings but those of values kept as written, and of an object listed without a section (the listing is
    kept too: the export lists it again, and its import says so again)."""
    return [w for w in warnings if (w.key or "").lower() not in KEPT_AS_WRITTEN and "is listed but has no" not in
            w.message]


@pytest.mark.parametrize(("name", "content", "case"), CORPUS, ids=[c[0] for c in CORPUS])
def test_export_of_a_corpus_file_reads_back_as_the_same_profile(name: str, content: bytes, case: Case) -> None:
    profile = read_eds(content, source=name).profile
    again = read_eds(export_eds(profile), source=name)
    assert again.profile == profile
    assert not_of_kept_texts(again.warnings) == []


def test_keys_the_model_has_no_field_for_are_kept_and_exported() -> None:
    name, content, _ = next(f for f in CORPUS_FILES if "domain-upload-download-file" in f[0])
    profile = read_eds(content, source=name).profile
    firmware = next(o for o in profile.objects if o.index == 0x2009)
    assert firmware.section_keys == {"UploadFile": "fw_read.bin", "DownloadFile": "fw.bin"}
    assert "UploadFile=fw_read.bin\nDownloadFile=fw.bin\n" in export_eds(profile)
    assert read_xdd(export_xdd(profile), source="x.xdd").profile.objects == profile.objects


def test_readings_of_numbers_and_formulas() -> None:
    assert read_int("0x180 (COB-ID)") == (0x180, "text after the number ignored ('(COB-ID)')")
    assert read_int("010")[0] == 8 and read_int("09")[0] == 9 and read_int("100.0")[0] == 100
    assert node_expr("$NODEID+0x180") == 0x180 and node_expr("0x100 + $NODEID + 0x80") == 0x180
    assert node_expr("$NODEID") == 0 and node_expr("0x600+$NODEID-1") == 0x5FF
    for bad in ("$NODEID*2", "$NODEID+$NODEID", "0x100-$NODEID", "$NODEID+x"):
        with pytest.raises(ValueError):
            node_expr(bad)


# --- properties over generated quirky files ---------------------------------------------------------------
_LINE_ENDS = st.sampled_from(["\n", "\r\n", "\r"])
_ENCODINGS = st.sampled_from(["utf-8", "utf-8-sig", "cp1252"])
_COMBINABLE = [c for c in CASES if c.encoding == "utf-8" and c.name not in ("dos-eof-mark", "no-final-newline",
                                                                             "crlf-line-ends", "cr-line-ends")]


def _combined(cases: list[Case], line_end: str, encoding: str) -> bytes:
    text = BASE
    for case in cases:
        try:
            text = case.quirk(text)
        except (AssertionError, ValueError):  # an earlier quirk removed what this one changes
            continue
    text = text.replace("\n", line_end)
    return (b"\xef\xbb\xbf" if encoding == "utf-8-sig" else b"") + text.encode(
        "utf-8" if encoding == "utf-8-sig" else encoding, errors="replace")


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(st.sampled_from(_COMBINABLE), min_size=1, max_size=6, unique_by=lambda c: c.name), _LINE_ENDS,
       _ENCODINGS)
def test_files_with_several_quirks_are_accepted_and_round_trip(cases: list[Case], line_end: str,
                                                                encoding: str) -> None:
    content = _combined(cases, line_end, encoding)
    imported = read_eds(content, source="combined.eds")
    again = read_eds(export_eds(imported.profile), source="combined.eds")
    assert again.profile == imported.profile and not_of_kept_texts(again.warnings) == []


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.data())
def test_mutated_files_are_accepted_or_refused_in_words(data: st.DataObject) -> None:
    """Random byte edits of a valid file: the import reads it (with warnings) or refuses it with a ProfileError
    naming the file; it never raises anything else."""
    content = bytearray(BASE.encode())
    for _ in range(data.draw(st.integers(1, 12))):
        position = data.draw(st.integers(0, len(content) - 1))
        action = data.draw(st.sampled_from(["flip", "delete", "insert", "cut"]))
        if action == "flip":
            content[position] = data.draw(st.integers(0, 255))
        elif action == "delete":
            del content[position:position + data.draw(st.integers(1, 40))]
        elif action == "insert":
            content[position:position] = data.draw(st.binary(min_size=1, max_size=20))
        else:
            del content[position:]
        if not content:
            break
    try:
        imported = read_eds(bytes(content), source="mutated.eds")
    except ProfileError as exc:
        assert exc.source == "mutated.eds" and exc.detail
        return
    again = read_eds(export_eds(imported.profile), source="mutated.eds").profile
    if {0x1000, 0x1001, 0x1018} <= {o.index for o in imported.profile.objects}:
        assert again == imported.profile
    else:  # the export adds the CiA 301 mandatory objects the file lacked
        assert all(o in again.objects for o in imported.profile.objects)


_INDEX_SUB = re.compile(r"^([0-9A-F]{4})SUB([0-9A-F]{1,2})$")
_REGENERATED = {"MANDATORYOBJECTS", "OPTIONALOBJECTS", "MANUFACTUREROBJECTS"}
"""Object lists are written from the objects read (their counts and order are the export's)."""


def _sections(text: str, name: str) -> dict[str, Section]:
    def same_sub(section: str) -> str:  # [1018sub01] is [1018sub1]
        found = _INDEX_SUB.match(section)
        return f"{found.group(1)}SUB{int(found.group(2), 16):X}" if found else section
    return {same_sub(n): s for n, s in parse_ini(text, name, Warnings(name)).items()}


@pytest.mark.parametrize(("name", "content"), [(n, c) for n, c, _ in CORPUS] + [
    (p.name, p.read_bytes()) for p in sorted(DATA_EDS.iterdir())], ids=lambda v: v if isinstance(v, str) else "")
def test_the_export_writes_every_key_of_the_file_or_the_import_said_why(name: str, content: bytes) -> None:
    """A regenerated EDS (not the kept bytes) holds every section and key of the file it was imported from,
    ObjectType of sub-objects, ObjFlags, CompactSubObj, Denotation, ParameterValue, UploadFile and [Comments]
    included; a key left out is in a section the import warned about (a quirk's reading)."""
    imported = read_eds(content, source=name)
    warned = {w.line for w in imported.warnings}
    original = _sections(decode_text(content, name), name)
    exported = _sections(export_eds(imported.profile), name)
    starts = sorted(s.line for s in original.values())
    for upper, section in original.items():
        if upper in _REGENERATED or (upper == "COMMENTS" and not imported.profile.notes):
            continue
        end = next((line for line in starts if line > section.line), 1 << 30)
        said = any(section.line <= line < end for line in warned)
        written = exported.get(upper)
        for key in section.keys.values():
            if key.value.strip() and (written is None or written.get(key.name) is None):
                assert said, f"[{section.name}] {key.name}={key.value} (line {key.line}) is not exported"
            elif key.name.lower() == "objecttype" and not said:  # DOMAIN stays 0x2, a sub-object's 0x7 stays
                assert read_int(written.get(key.name).value) == read_int(key.value), key  # type: ignore[union-attr]
