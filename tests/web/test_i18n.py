"""The German UI: every text of the templates and of the problem details has a German catalogue entry, and the real
HTTP API answers in the language the switch or the browser asks for, numbers written as that language writes them."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
from babel.messages.extract import extract_from_dir
from babel.messages.frontend import parse_mapping_cfg
from babel.messages.pofile import read_po
from fastapi.testclient import TestClient

from drivebench import i18n

ROOT = Path(__file__).resolve().parents[2]
DE_PO = i18n.LOCALE_DIR / "de" / "LC_MESSAGES" / "messages.po"
SESSION = "demo-plant"
GERMAN = {"Accept-Language": "de-DE,de;q=0.9,en;q=0.5"}
# Tests marked only_reads share the module's one demo-plant app (tests/conftest.py client); the others start their own.


def _extracted() -> dict[str, str]:
    """Every text pybabel extract finds (babel.cfg: the Python code and the templates), with where it is."""
    with (ROOT / "babel.cfg").open() as cfg:
        method_map, options_map = parse_mapping_cfg(cfg)
    found: dict[str, str] = {}
    for filename, lineno, message, _comments, _context in extract_from_dir(str(ROOT), method_map, options_map):
        msgid = message if isinstance(message, str) else message[0]
        found.setdefault(msgid, f"{filename}:{lineno}")
    return found


def _german() -> dict[str, object]:
    with DE_PO.open("rb") as po:
        catalog = read_po(po, locale="de")
    return {(m.id if isinstance(m.id, str) else m.id[0]): m for m in catalog if m.id}


def test_every_text_of_the_templates_and_code_has_a_german_translation() -> None:
    extracted, german = _extracted(), _german()
    assert any(where.startswith("frontend/templates/node/") for where in extracted.values())  # templates were read
    assert "Plant" in extracted and "Not signed in" in extracted  # a template text and an error title
    missing = [f"{where}: {msgid!r}" for msgid, where in sorted(extracted.items())
               if msgid not in german or "fuzzy" in german[msgid].flags  # type: ignore[attr-defined]
               or not all(german[msgid].string if isinstance(german[msgid].string, tuple)  # type: ignore[attr-defined]
                          else [german[msgid].string])]  # type: ignore[attr-defined]
    assert not missing, "no German catalogue entry (run `make i18n-update` and translate):\n" + "\n".join(missing)


PLACEHOLDER = re.compile(r"%\((\w+)\)s|\{(\w+)\}")


def test_german_texts_keep_the_placeholders_of_the_english() -> None:
    wrong = []
    for msgid, message in _german().items():
        strings = message.string if isinstance(message.string, tuple) else (message.string,)  # type: ignore[attr-defined]
        wanted = set(PLACEHOLDER.findall(msgid))
        wrong += [f"{msgid!r} -> {text!r}" for text in strings if text and set(PLACEHOLDER.findall(text)) != wanted]
    assert not wrong, "\n".join(wrong)


# Text left outside gettext in a template: a text node or a shown attribute with a word in it. Jinja code, scripts
# and <code> are left out; what remains must be a symbol, a number or one of these words that read the same in both.
_JINJA = re.compile(r"\{%-?\s*trans\b.*?\{%-?\s*endtrans\s*-?%\}|\{\{.*?\}\}|\{%.*?%\}|\{#.*?#\}", re.S)
_RAW = re.compile(r"<(script|style|code|pre|textarea)\b[^>]*>.*?</\1>", re.S | re.I)
_SHOWN_ATTRIBUTES = re.compile(r'\s(?:title|placeholder|aria-label|hx-confirm|alt)="([^"]*)"')
SAME_IN_BOTH = {"DriveBench", "TEC", "REC", "kbit", "ms", "mm", "s", "expedited"}  # expedited: CiA 301 transfer name


def test_no_english_text_is_left_outside_gettext_in_the_templates() -> None:
    left = []
    for template in sorted((ROOT / "frontend" / "templates").rglob("*.html")):
        source = _RAW.sub("<raw></raw>", _JINJA.sub("\x00", template.read_text()))
        pieces = re.findall(r">([^<>]+)<", source) + _SHOWN_ATTRIBUTES.findall(source)
        for piece in pieces:
            words = {w for w in re.findall(r"[A-Za-z]{2,}", piece) if w not in SAME_IN_BOTH}
            if words:
                left.append(f"{template.relative_to(ROOT)}: {piece.strip()[:100]!r}")
    assert not left, "English text outside {% trans %} / _():\n" + "\n".join(left)


def test_the_language_comes_from_the_switch_else_the_browser() -> None:
    assert i18n.negotiate("de-AT,de;q=0.9,en;q=0.8") == "de"
    assert i18n.negotiate("fr-FR, de;q=0.5, en;q=0.4") == "de"  # the first one we have
    assert i18n.negotiate("en-GB,en;q=0.9,de;q=0.8") == "en"
    assert i18n.negotiate("de;q=0, en") == "en"  # q=0: not German
    assert i18n.negotiate(None) == "en" and i18n.negotiate("fr") == "en"
    assert i18n.negotiate("de", cookie="en") == "en" and i18n.negotiate("en", cookie="de") == "de"
    assert i18n.negotiate("de", cookie="xx") == "de"  # a cookie naming no language we have is ignored


def test_numbers_as_each_language_writes_them() -> None:
    with i18n.using("de"):
        assert i18n.number(1234.5) == "1.234,5"
        assert i18n.number(1234.5, 2) == "1.234,50"
    with i18n.using("en"):
        assert i18n.number(1234.5) == "1,234.5"


@pytest.mark.only_reads
def test_accept_language_german_gives_the_german_plant_page(client: TestClient) -> None:
    page = client.get("/", headers=GERMAN)
    assert page.status_code == 200
    assert '<html lang="de">' in page.text
    assert "<h1>Anlage</h1>" in page.text and "Sitzung öffnen" in page.text and "Bus scannen" in page.text
    assert "Open session" not in page.text
    assert {v.strip() for v in page.headers["vary"].split(",")} >= {"Accept-Language", "Cookie"}
    assert page.headers["content-language"] == "de"
    assert "Der Antrieb kann sich bewegen" in page.text  # app.js's texts, handed to it as JSON (js-messages)
    english = client.get("/")
    assert 'id="js-messages"' not in english.text
    assert '<html lang="en">' in english.text and "<h1>Plant</h1>" in english.text and "Open session" in english.text


@pytest.mark.only_reads
def test_a_refusal_of_the_gate_speaks_the_browsers_language_and_says_so(client: TestClient) -> None:
    """The gate picks the language before it refuses anything: another site's POST is refused in German, with the
    same Vary and Content-Language as a page."""
    refused = client.post("/api/sessions", json={}, headers={**GERMAN, "Origin": "https://evil.example",
                                                             "Sec-Fetch-Site": "cross-site"})
    assert refused.status_code == 403
    assert "Eine andere Website darf an DriveBench nichts ändern" in refused.json()["detail"]
    assert refused.headers["content-language"] == "de"
    assert {v.strip() for v in refused.headers["vary"].split(",")} >= {"Accept-Language", "Cookie"}
    switched = client.get("/api/health", headers={**GERMAN, "Cookie": f"{i18n.COOKIE}=en"})
    assert switched.headers["content-language"] == "en"  # the switch's cookie wins over the browser


def test_an_answer_keeps_its_own_vary_names_and_language() -> None:
    from drivebench.web.language import varying

    assert varying([(b"vary", b"Origin")], "de") == [(b"vary", b"Origin, Accept-Language, Cookie"),
                                                     (b"content-language", b"de")]
    assert varying([(b"Vary", b"cookie, accept-language"), (b"Content-Language", b"en")], "de") == [
        (b"Vary", b"cookie, accept-language"), (b"Content-Language", b"en")]
    assert varying([], "en") == [(b"vary", b"Accept-Language, Cookie"), (b"content-language", b"en")]


@pytest.mark.only_reads
def test_the_switch_sets_a_cookie_that_overrides_the_browser(client: TestClient) -> None:
    switched = client.get("/language/en?next=/monitor", headers=GERMAN, follow_redirects=False)
    assert switched.status_code == 303 and switched.headers["location"] == "/monitor"
    assert "drivebench_lang=en" in switched.headers["set-cookie"]
    page = client.get("/", headers=GERMAN)  # the test client keeps the cookie
    assert '<html lang="en">' in page.text and "<h1>Plant</h1>" in page.text
    client.get("/language/de", follow_redirects=False)
    assert "<h1>Anlage</h1>" in client.get("/", headers={"Accept-Language": "en"}).text
    # the switch never sends anyone to another site
    for target in ("//evil.example/", "https://evil.example/", "/\\evil.example"):
        assert client.get("/language/de", params={"next": target}, follow_redirects=False).headers["location"] == "/"


@pytest.mark.only_reads
def test_the_header_switch_links_both_languages_back_to_this_page(client: TestClient) -> None:
    page = client.get("/tools?x=1", headers=GERMAN).text
    assert 'href="/language/en?next=/tools%3Fx%3D1"' in page
    assert re.search(r'id="lang-de"\s+class="active" aria-current="true"', page)


def test_the_parameters_tab_in_german_with_german_numbers(client: TestClient) -> None:
    written = client.put(f"/api/sessions/{SESSION}/nodes/5/parameters/C00088", json={"value": 1234.5})
    assert written.status_code == 200, written.text
    assert written.json()["read_back"]["display"] == "1234.50 A"  # the JSON API keeps one number format
    tab = client.get(f"/sessions/{SESSION}/nodes/5?tab=parameters", headers=GERMAN).text
    assert ">Parameter</a>" in tab and "Alle lesen" in tab and "Neuer Wert" in tab
    assert "Rated motor current" in tab  # the vendor's name as the manual prints it: no name_de in this profile
    profile = client.app.state.drivebench.registry.get("lenze-8400-motec-canopen")  # type: ignore[attr-defined]
    rated_current = next(p for p in profile.parameters if p.code == "C00088")
    rated_current.name_de = "Motor-Bemessungsstrom"  # as a profile with the German manual's names would give it
    tab = client.get(f"/sessions/{SESSION}/nodes/5?tab=parameters&q=C00088", headers=GERMAN).text
    assert "Motor-Bemessungsstrom" in tab and "Rated motor current" not in tab
    assert "Rated motor current" in client.get(f"/sessions/{SESSION}/nodes/5?tab=parameters&q=C00088").text
    row = client.post(f"/ui/sessions/{SESSION}/nodes/5/parameters/C00088/read",
                      headers={**GERMAN, "HX-Request": "true", "X-DriveBench": "1"})
    assert row.status_code == 200, row.text
    assert ">1.234,50 A</span>" in row.text and "Lesen" in row.text
    english = client.post(f"/ui/sessions/{SESSION}/nodes/5/parameters/C00088/read",
                          headers={"HX-Request": "true", "X-DriveBench": "1"})
    assert ">1234.50 A</span>" in english.text


def test_problem_details_follow_the_language_and_stay_english_by_default(client: TestClient) -> None:
    unknown = client.get(f"/api/sessions/{SESSION}/nodes/99/parameters/C00088", headers=GERMAN)
    assert unknown.status_code == 404
    assert unknown.json()["title"] == "Nicht gefunden"
    assert unknown.json()["detail"].startswith("Knoten 99 gehört nicht zur Sitzung")
    assert unknown.json()["type"] == "/problems/not-found"  # what scripts branch on never changes
    plain = client.get(f"/api/sessions/{SESSION}/nodes/99/parameters/C00088")
    assert plain.json()["title"] == "Not found" and plain.json()["detail"].startswith("Node 99 is not part of")
    # confirmation naming the node, in German for a German browser
    start = client.post(f"/api/sessions/{SESSION}/nodes/5/nmt", json={"command": "start"}, headers=GERMAN)
    assert start.status_code == 428
    assert start.json()["title"] == "Bestätigung erforderlich" and "Knoten 5" in start.json()["detail"]
    assert "confirm = '5'" in start.json()["detail"]  # what app.js reads to ask and send the confirmation again
    # a page that does not exist, as a browser opens it
    missing = client.get("/nowhere", headers={**GERMAN, "Accept": "text/html"})
    assert missing.status_code == 404 and "Seite nicht gefunden" in missing.text and "Unter /nowhere" in missing.text
    # validation
    invalid = client.put(f"/api/sessions/{SESSION}/nodes/5/parameters/C00088", json={}, headers=GERMAN)
    assert invalid.status_code == 422 and invalid.json()["title"] == "Ungültige Anfrage"


def test_a_profile_name_de_is_shown_in_german_only(registry: object) -> None:
    from drivebench.device.profiles.catalog import Item
    from drivebench.device.profiles.profile import Parameter

    entry = Parameter(code="C00088", name="Rated motor current", name_de="Motor-Bemessungsstrom",
                      data_type="UNSIGNED32", unit="A", factor=100)  # type: ignore[arg-type]
    item = Item(ref="C00088", index=0x5FA7, subindex=0, entry=entry)
    assert item.name_for("de") == "Motor-Bemessungsstrom" and item.name_for("en") == item.name == "Rated motor current"
    plain = Item(ref="C00089", index=0x5FA6, subindex=0, entry=Parameter(code="C00089", name="Rated motor voltage",
                                                                           data_type="UNSIGNED32"))  # type: ignore[arg-type]
    assert plain.name_for("de") == "Rated motor voltage"  # no German name in the profile: the manual's own


@pytest.mark.only_reads
@pytest.mark.parametrize("path", ["/", "/monitor", "/tools", "/parameter-sets", "/profiles", "/remote",
                                  "/profiles/lenze-8400-motec-canopen", "/monitor/ethercat-line",
                                  "/sessions/ethercat-line/nodes/1?tab=pdo",
                                  f"/sessions/{SESSION}/nodes/5?tab=parameters", f"/sessions/{SESSION}/nodes/5?tab=pdo",
                                  f"/sessions/{SESSION}/nodes/5?tab=diagnostics",
                                  f"/sessions/{SESSION}/nodes/7?tab=control", f"/sessions/{SESSION}/nodes/5?tab=info"])
@pytest.mark.slow  # among the costliest of the quick subset (--durations, issue 29): `make test-quick` leaves it out
def test_every_screen_renders_in_german(client: TestClient, path: str) -> None:
    page = client.get(path, headers=GERMAN)
    assert page.status_code == 200, page.text[:500]
    assert '<html lang="de">' in page.text and 'aria-label="Ansichten"' in page.text


def _script_messages(page: str) -> dict[str, str]:
    block = re.search(r'<script type="application/json" id="js-messages">(.*?)</script>', page, re.S)
    assert block, "no js-messages block in the page"
    return json.loads(block.group(1))


@pytest.mark.only_reads
def test_the_control_and_pdo_scripts_texts_reach_the_page_in_german(client: TestClient) -> None:
    """control.js and pdo.js build texts in the browser: they are extracted, translated and handed to the page."""
    extracted = _extracted()
    for text, script in (("armed by another panel", "control.js"),
                         ("Hold to jog {way} at {value} {unit}", "control.js"),
                         ("No entries: the PDO carries nothing.", "pdo.js"), ("byte {byte}: free", "pdo.js")):
        assert extracted.get(text, "").startswith(f"frontend/static/{script}"), text
    control = _script_messages(client.get(f"/sessions/{SESSION}/nodes/7?tab=control", headers=GERMAN).text)
    assert control["armed by another panel"] == "von einem anderen Panel scharf geschaltet"
    assert control["Hold to jog {way} at {value} {unit}"] == "Halten: Tippen {way} mit {value} {unit}"  # filled there
    pdo = _script_messages(client.get(f"/sessions/{SESSION}/nodes/5?tab=pdo", headers=GERMAN).text)
    assert pdo["No entries: the PDO carries nothing."] == "Keine Einträge: Das PDO überträgt nichts."


def test_service_error_details_follow_the_language(client: TestClient) -> None:
    """Details built deep in the services (scaling, the SDO client) come back German to a German browser and
    unchanged English to everyone else."""
    url = f"/api/sessions/{SESSION}/nodes/5/parameters/C00088"
    german = client.put(url, json={"value": 10**9}, headers=GERMAN)
    assert german.status_code == 422, german.text
    assert german.json()["detail"] == ("C00088 (Rated motor current): 1000000000 passt nicht in den Datentyp "
                                       "UNSIGNED32 (roh 0 ... 4294967295)")
    english = client.put(url, json={"value": 10**9})
    assert english.json()["detail"] == ("C00088 (Rated motor current): 1000000000 does not fit the data type "
                                        "UNSIGNED32 (raw 0 ... 4294967295)")
    typed = client.put(url, json={"value": "viel"}, headers=GERMAN)
    assert typed.json()["detail"] == "C00088 (Rated motor current) erwartet eine Zahl, erhalten: 'viel'"

    plant = client.app.state.drivebench.plants[SESSION]  # type: ignore[attr-defined]
    plant.nodes[12].power_off()  # the SDO request is sent and never answered
    try:
        silent = client.get(f"/api/sessions/{SESSION}/nodes/12/parameters/0x1000", headers=GERMAN)
        assert silent.json()["type"] == "/problems/sdo-timeout-error", silent.text
        assert silent.json()["detail"].startswith("Knoten 12 hat auf die SDO-Anfrage für 0x1000sub0 nicht geantwortet")
        assert silent.json()["hint"].startswith("Prüfen Sie, ob der Knoten Spannung hat")
        plain = client.get(f"/api/sessions/{SESSION}/nodes/12/parameters/0x1000").json()
        assert plain["detail"].startswith("Node 12 did not answer the SDO request for 0x1000sub0 (")
        assert plain["hint"].startswith("Check that the node is powered")
    finally:
        plant.nodes[12].power_on()


def test_a_catalogue_without_its_mo_is_compiled_from_the_po(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A clean clone (no make install) or a .po edited after the last compile: Babel compiles the .po in memory."""
    messages = tmp_path / "de" / "LC_MESSAGES"
    messages.mkdir(parents=True)
    (messages / "messages.po").write_bytes(DE_PO.read_bytes())
    monkeypatch.setattr(i18n, "LOCALE_DIR", tmp_path)
    i18n.translations.cache_clear()
    try:
        with i18n.using("de"):
            assert i18n.gettext("Plant") == "Anlage"
            assert i18n.ngettext("%(count)s warning", "%(count)s warnings", 2) == "%(count)s Warnungen"
        assert not (messages / "messages.mo").exists()  # nothing written into the package
    finally:
        i18n.translations.cache_clear()


@pytest.mark.only_reads
def test_the_plant_pages_websocket_pushes_the_table_in_the_asked_language(client: TestClient) -> None:
    with client.websocket_connect(f"/ws/sessions/{SESSION}/nodes", headers=GERMAN) as socket:
        table = socket.receive_text()
    assert "NMT-Zustand" in table and "NMT state" not in table
    with client.websocket_connect(f"/ws/sessions/{SESSION}/nodes") as socket:
        assert "NMT state" in socket.receive_text()


# --- problem details written in the code ----------------------------------------------------------------------------
# An error built from an English literal (a plain string, an f-string, "...".format()) reaches a German user in English:
# every text given to a DriveBench error as its detail or hint goes through _() (in a request: the reader's language),
# or an i18n.Text of an N_() template (raised outside a request, translated when shown).
def _error_classes() -> set[str]:
    import inspect

    from drivebench import errors

    return {name for name, cls in vars(errors).items()
            if inspect.isclass(cls) and issubclass(cls, errors.DriveBenchError)}


def _english_literal(node: object) -> bool:
    import ast

    if isinstance(node, ast.JoinedStr) or (isinstance(node, ast.Constant) and isinstance(node.value, str)):
        return True
    if isinstance(node, ast.BinOp):
        return _english_literal(node.left) or _english_literal(node.right)
    if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "format":
        return _english_literal(node.func.value)
    return False


def untranslated_error_texts(package: Path) -> list[str]:
    import ast

    classes = _error_classes()
    found = []
    for source in sorted(package.rglob("*.py")):
        for node in ast.walk(ast.parse(source.read_text())):
            if not isinstance(node, ast.Call):
                continue
            called = node.func.attr if isinstance(node.func, ast.Attribute) else getattr(node.func, "id", None)
            if called not in classes:
                continue
            texts = list(node.args[:1]) + [k.value for k in node.keywords if k.arg in ("detail", "hint")]
            if any(_english_literal(text) for text in texts):
                found.append(f"{source.relative_to(ROOT)}:{node.lineno}")
    return found


def test_every_error_text_in_the_code_is_translatable() -> None:
    left = untranslated_error_texts(ROOT / "backend" / "drivebench")
    assert not left, f"{len(left)} error texts given as English literals (wrap in _() or i18n.Text(N_(...))):\n" \
                     + "\n".join(left)


# --- the page scripts ---------------------------------------------------------------------------------------------
# A text a script puts on the page goes through _() (drivebench.gettext); these sinks show text to a user.
_JS_SINKS = [re.compile(r"\.(?:textContent|innerText|innerHTML|title|placeholder|ariaLabel)\s*(?:\+?=)\s*([^;]*)"),
             re.compile(r"\b(?:alert|confirm|prompt|errorBox|setCustomValidity)\(([^;]*)"),
             re.compile(r"\b(?:append|replaceChildren|prepend|insertAdjacentHTML|insertAdjacentText)\(([^;]*)"),
             re.compile(r"\bel\(\s*\"\w+\"\s*,\s*(?:\{[^{}]*\}|null|undefined)\s*,([^;]*)"),
             re.compile(r"\blabel:\s*(\"[^\"]*\"|'[^']*')")]
_JS_LITERAL = re.compile(r"\"(?:[^\"\\\n]|\\.)*\"|'(?:[^'\\\n]|\\.)*'|`[^`]*`")
_JS_TRANSLATED = re.compile(r"\b(?:_|gettext)\(\s*(?:\"(?:[^\"\\]|\\.)*\"|'(?:[^'\\]|\\.)*'|`[^`]*`)"
                            r"(?:\s*\+\s*(?:\"(?:[^\"\\]|\\.)*\"|'(?:[^'\\]|\\.)*'))*")
# Literals that are no text: tag names (el("span"), createElement("div")), element properties (className: "x"),
# where insertAdjacentHTML puts it ("beforeend"), ids
# looked up ($("trace-body")) and values compared with (state === "bus-off").
_JS_NOT_TEXT = re.compile(r"(\bel\(|\bcreateElement\(|\binsertAdjacent\w+\(|\$\(|\bgetElementById\("
                          r"|\bquerySelector(?:All)?\(|[=!]==?"
                          r"|\b(?:className|id|type|name|href|src|method|role|rel|target|kind)\s*:)"
                          r"\s*(\"[^\"]*\"|'[^']*')")
_JS_SHOWN_ATTRIBUTE = {"title", "aria-label", "placeholder", "alt"}
# Words that read the same in both languages (units, CAN terms, the product's name).
JS_SAME_IN_BOTH = SAME_IN_BOTH | {"HTTP", "min"}


def _template_parts(template: str) -> tuple[str, list[str]]:
    """A template literal's text (the ${…} taken out) and the expressions whose value becomes text (not those inside
    an attribute such as class="…", which no one reads)."""
    text, shown, depth, start, i = [], [], 0, 0, 0
    while i < len(template):
        if depth == 0 and template.startswith("${", i):
            text.append(template[start:i])
            depth, start, i = 1, i + 2, i + 2
            continue
        if depth:
            depth += {"{": 1, "}": -1}.get(template[i], 0)
            if depth == 0:
                before = "".join(text)
                attribute = re.search(r"([\w-]+)=\"[^\"]*$", before)
                if attribute is None or attribute.group(1) in _JS_SHOWN_ATTRIBUTE:
                    shown.append(template[start:i])
                start = i + 1
        i += 1
    text.append(template[start:])
    return "".join(text), shown


def _english_words(text: str) -> set[str]:
    shown = " ".join(_SHOWN_ATTRIBUTES.findall(text)) + " " + re.sub(r"<[^<>]*>", " ", text)
    return {w for w in re.findall(r"[A-Za-z]{2,}", shown) if w not in JS_SAME_IN_BOTH}


def _english_in(expression: str) -> list[str]:
    found = []
    for literal in _JS_LITERAL.findall(expression):
        body = literal[1:-1]
        if literal.startswith("`"):
            body, shown = _template_parts(body)
            found += [english for inner in shown for english in _english_in(inner)]
        if _english_words(body):
            found.append(literal)
    return found


def english_script_texts(source: str) -> list[str]:
    """Literals with English words a script shows (textContent, title, innerHTML, alerts, error boxes, el()
    children, chart labels) without _()."""
    code = re.sub(r"(^|\s)//[^\n]*", r"\1", source)  # comments (not the // of a URL in a string)
    code = _JS_TRANSLATED.sub('_(""', code)
    code = _JS_NOT_TEXT.sub(lambda m: m.group(0)[:m.start(2) - m.start(0)] + '""', code)
    return sorted({english for sink in _JS_SINKS for match in sink.finditer(code)
                   for english in _english_in(match.group(1))})


def test_the_script_check_finds_english_left_outside_gettext() -> None:
    assert english_script_texts('badge.textContent = { live: "live", down: "retrying" }[state];') == [
        '"live"', '"retrying"']
    assert english_script_texts('x.innerHTML = `<td title="${esc(r.name || "not here")}">${n} s</td>`;') == [
        '"not here"']
    assert english_script_texts("alert('Saved.'); box.append(el(\"span\", {}, \"at once\"));") == [
        '"at once"', "'Saved.'"]
    assert not english_script_texts('x.textContent = _("Pause"); y.title = _("{n} ms", {n}) + " · TEC";')
    assert not english_script_texts('row.innerHTML = `<tr class="${r.rate ? "" : "silent"}"><td>${num(n)}</td>`;')


def test_every_text_a_script_marks_is_extracted() -> None:
    """pybabel's JavaScript extractor misses a _() inside a template literal's ${…}: such a text would have no
    catalogue entry and stay English on a German page."""
    marked = re.compile(r"\b_\(\s*(\"(?:[^\"\\]|\\.)*\"(?:\s*\+\s*\"(?:[^\"\\]|\\.)*\")*)")
    missed = []
    for script in sorted((ROOT / "frontend" / "static").glob("*.js")):
        extracted = {message for _line, message, _c, _ctx in extract_from_file_js(script)}
        for literal in marked.findall(re.sub(r"(^|\s)//[^\n]*", r"\1", script.read_text())):
            text = "".join(json.loads(part) for part in re.findall(r'"(?:[^"\\]|\\.)*"', literal))
            if text not in extracted:
                missed.append(f"{script.name}: {text!r}")
    assert not missed, "_() texts pybabel does not extract (take them out of the template literal):\n" + "\n".join(
        missed)


def test_no_page_script_shows_english_outside_gettext() -> None:
    left = [f"{script.name}: {text}" for script in sorted((ROOT / "frontend" / "static").glob("*.js"))
            for text in english_script_texts(script.read_text())]
    assert not left, "English text a script shows without _():\n" + "\n".join(left)


_PAGES_WITH_SCRIPTS = ["/", "/monitor", "/tools", "/parameter-sets", "/profiles",
                       f"/sessions/{SESSION}/nodes/5?tab=parameters", f"/sessions/{SESSION}/nodes/5?tab=pdo",
                       f"/sessions/{SESSION}/nodes/7?tab=control"]


@pytest.mark.only_reads
@pytest.mark.parametrize("path", _PAGES_WITH_SCRIPTS)
def test_each_page_hands_its_scripts_their_german_texts(client: TestClient, path: str) -> None:
    """Every _()-text of every script a German page loads is in that page's js-messages, translated."""
    page = client.get(path, headers=GERMAN).text
    messages = _script_messages(page)
    scripts = re.findall(r'<script src="/static/(\w+\.js)"', page)
    assert "app.js" in scripts
    german = _german()
    same_in_german = {msgid for msgid, entry in german.items() if entry.string == msgid}  # type: ignore[attr-defined]
    untranslated = []
    for script in scripts:
        texts = [message for _line, message, _c, _ctx in extract_from_file_js(ROOT / "frontend" / "static" / script)]
        untranslated += [f"{script}: {text!r}" for text in texts
                         if not messages.get(text) or (messages[text] == text and text not in same_in_german)]
    assert not untranslated, "\n".join(untranslated)


def extract_from_file_js(path: Path) -> list[tuple[int, str, list[str], str | None]]:
    from babel.messages.extract import extract_from_file

    return [(line, message if isinstance(message, str) else message[0], comments, context)
            for line, message, comments, context in extract_from_file("javascript", str(path))]


def test_the_simulators_fault_panel_and_refusals_in_german(client: TestClient) -> None:
    url = f"/api/sessions/{SESSION}/simulator/nodes/5/faults"
    try:
        faults = client.put(url, json={"abort_code": "0x08000022", "abort_every": 3, "latency_ms": 20.5},
                            headers=GERMAN)
        assert faults.status_code == 200, faults.text
        assert faults.json()["active"] == ["bricht jede 3. Anfrage mit 0x08000022 ab", "20,5 ms zusätzliche SDO-Latenz"]
        assert client.get(url).json()["active"][0] == "aborts every 3th request with 0x08000022"
    finally:
        client.delete(url)
    missing = client.get(f"/api/sessions/{SESSION}/simulator/nodes/99/faults", headers=GERMAN)
    assert missing.status_code == 404
    assert missing.json()["detail"] == f"Die simulierte Anlage der Sitzung '{SESSION}' hat keinen Knoten 99"
    wrong = client.put(url, json={"abort_code": "viele"}, headers=GERMAN)
    assert wrong.status_code == 422 and "abort_code muss eine Zahl sein" in wrong.text


def test_the_info_tab_names_the_device_profile_in_german() -> None:
    from drivebench.web.pages.node_info import identity_text

    with i18n.using("de"):
        assert identity_text("0x1000", 0x00020192) == "CiA 402 Antriebe und Bewegungssteuerung, Zusatzinformation 2"
        assert identity_text("0x1000", 0x1F4) == "Geräteprofil 500"
    assert identity_text("0x1000", 0x192) == "CiA 402 drives and motion control"


_PLURAL_WITHOUT_NAME = (r"\{%-?\s*trans\s+([^%]*?)-?%\}(?:(?!\{%-?\s*endtrans).)*?"
                        r"\{%-?\s*pluralize\s*-?%\}")


def test_a_plural_in_a_template_counts_with_its_number() -> None:
    """{% pluralize %} counts with the first variable of its {% trans %}: a text there (not the count) breaks the
    German page (gettext needs a number for the plural form; English never asks)."""
    wrong = []
    for template in sorted((ROOT / "frontend" / "templates").rglob("*.html")):
        for variables in re.findall(_PLURAL_WITHOUT_NAME, template.read_text(), re.S):
            first = variables.split("=", 1)[0].strip()
            if "=" in variables and first != "count":
                wrong.append(f"{template.relative_to(ROOT)}: trans {variables.strip()[:80]}")
    assert not wrong, "name the count: {% pluralize count %}\n" + "\n".join(wrong)


def test_the_write_lease_names_where_it_comes_from_in_the_readers_language(client: TestClient) -> None:
    """The lease keeps where a write came from in English (others read it later, in their language)."""
    written = client.put(f"/api/sessions/{SESSION}/nodes/5/parameters/C00088", json={"value": 12.5})
    assert written.status_code == 200, written.text
    try:
        banner = client.get(f"/ui/sessions/{SESSION}/nodes/5/lease", headers=GERMAN).text
        assert "Sie haben das Schreibrecht auf Knoten 5 (Parameter-API)" in banner, banner
        assert "(Parameters API)" in client.get(f"/ui/sessions/{SESSION}/nodes/5/lease").text
    finally:
        client.post(f"/ui/sessions/{SESSION}/nodes/5/lease/release", headers={"HX-Request": "true",
                                                                               "X-DriveBench": "1"})
