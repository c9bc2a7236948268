"""The profile registry: every device profile the tool knows, from the built-in directory and user uploads.

Built-in profiles are ``settings.profiles_dir/*.json``, plus ``*.eds``/``*.dcf`` files whose profile id has no JSON
twin (the JSON is the richer source: vendor codes, scaling, selection lists). Uploads live in
``settings.user_profiles_dir`` under a name made from the profile id, never the uploaded file name.
A file that does not load is kept in ``errors`` as (file name, message); the others still load.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import tempfile
import threading
import unicodedata
from collections.abc import Callable
from dataclasses import dataclass
from dataclasses import field as dataclass_field
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from drivebench.config import settings
from drivebench.device.calculators.dip import clash
from drivebench.device.drive.motion import ignored_still_values
from drivebench.device.formats.eds import ImportWarning, read_eds
from drivebench.device.formats.json_lines import DuplicateKey, JsonPath, line_of, reject_duplicate_keys, value_lines
from drivebench.device.formats.xdd import XML_SUFFIXES, read_xdd
from drivebench.device.profiles.parsed_cache import Parsed, ParsedCache
from drivebench.device.profiles.profile import ObjectEntry, Parameter, Profile
from drivebench.errors import ProfileError, UnknownProfile
from drivebench.i18n import N_, Text, shown

PROFILE_SUFFIXES = (".json", ".eds", ".dcf", ".xdd", ".xdc")
KINDS = {".json": N_("this looks like a JSON profile, name it .json"),
         ".eds": N_("this looks like an EDS, name it .eds"),
         ".xdd": N_("this looks like an XDD/XDC (XML), name it .xdd")}
IGNORED_STILL = N_("the still value '{value}' is ignored: a word it matches could still enable the drive from some "
                   "state (a control word's still value must hold a blocking bit of the profile's control section, "
                   "never the fault reset; a setpoint's is 0; a standard object's cannot be weaker than the "
                   "standard's)")
UPLOAD_NAMES_SUFFIX = ".names.json"
"""Beside the upload directory (``var/profiles.names.json``): profile id -> the file name it was uploaded as
(shown, never used as a path)."""
MAX_ID_CHARS = 100
MAX_SHOWN_NAME_CHARS = 120
# Names Windows keeps for devices, with any extension ("con.eds" opens the console there).
WINDOWS_DEVICE_NAMES = {"con", "prn", "aux", "nul", *(f"com{n}" for n in range(10)), *(f"lpt{n}" for n in range(10))}


def shown_name(filename: str) -> str:
    """An uploaded file's name fit to show and to name in messages: its last path part (after ``/`` or ``\\``),
    without control or format characters (NUL, newlines, right-to-left overrides), at most 120 characters."""
    last = re.split(r"[/\\]", filename)[-1]
    cleaned = "".join(ch for ch in last if unicodedata.category(ch)[0] != "C").strip()
    if len(cleaned) > MAX_SHOWN_NAME_CHARS:  # shortened in the middle: the suffix says how to read the file
        suffix = Path(cleaned).suffix[:10]
        cleaned = cleaned[:MAX_SHOWN_NAME_CHARS - 1 - len(suffix)] + "…" + suffix
    return cleaned or "upload"


def _load_name(name: str) -> str:
    """The name the loader reads the upload under: ``.eds`` alone (a name that is only a suffix) -> ``upload.eds``."""
    return f"upload{name.lower()}" if name.lower() in PROFILE_SUFFIXES else name


@dataclass(frozen=True)
class LoadedFile:
    """A profile as read from its file: the readings applied to quirks (warnings) and the file's own bytes, kept
    so an unchanged file downloads back byte-identical and a DCF of it keeps its layout."""

    profile: Profile
    warnings: list[ImportWarning] = dataclass_field(default_factory=list)
    original: bytes | None = None
    """The bytes of an EDS/DCF/XDD/XDC file (None for a JSON profile: its JSON export is the file)."""
    suffix: str = ".json"

    def limits_note(self, index: int, subindex: int) -> str | None:
        """What the import did to this object's limits (repaired or dropped), for a write to say first."""
        notes = [shown(w.message) for w in self.warnings if w.limits and (w.index, w.subindex) == (index, subindex)]
        return "; ".join(notes) or None


def _original(profiles: object, profile: Profile, suffixes: tuple[str, ...]) -> bytes | None:
    if not isinstance(profiles, ProfileRegistry):
        return None
    try:
        loaded = profiles.loaded(profile.id)
    except UnknownProfile:
        return None
    return loaded.original if loaded.profile is profile and loaded.suffix in suffixes else None


def original_file(profiles: object, profile: Profile) -> bytes | None:
    """The EDS/DCF bytes ``profile`` was read from, when ``profiles`` is a registry that holds this very profile
    (a DCF of it is then written over the original file)."""
    return _original(profiles, profile, (".eds", ".dcf"))


def original_xml(profiles: object, profile: Profile) -> bytes | None:
    """The XDD/XDC bytes ``profile`` was read from, as :func:`original_file` (an XDC of it is then written over
    that file)."""
    return _original(profiles, profile, XML_SUFFIXES)


def load_profile_file(content: bytes, name: str) -> Profile:
    """One profile file's bytes -> Profile, by suffix. Raises ProfileError naming ``name`` (and line)."""
    return read_profile_file(content, name).profile


def read_profile_file(content: bytes, name: str) -> LoadedFile:
    """One profile file's bytes -> the profile, its warnings and the bytes. Raises ProfileError naming ``name``."""
    suffix = Path(name).suffix.lower()
    looks_like = _looks_like(content)
    if suffix in (".eds", ".dcf"):
        if looks_like == ".json":
            raise ProfileError(Text(N_("this is a JSON profile, not an EDS: name the file .json")), source=name, line=1)
        imported = read_eds(content, source=name)
        return LoadedFile(imported.profile, imported.warnings, content, suffix)
    if suffix in XML_SUFFIXES:
        imported = read_xdd(content, source=name)
        return LoadedFile(imported.profile, imported.warnings, content, suffix)
    if suffix != ".json":
        unknown = Text(N_("unknown profile file type {suffix}; use .json, .eds, .dcf, .xdd or .xdc"),
                       suffix=suffix or "(none)")
        raise ProfileError(Text.joined("; ", [unknown, Text(KINDS[looks_like])]) if looks_like else unknown,
                           source=name)
    if looks_like == ".xdd":
        raise ProfileError(Text(N_("this is an XDD/XDC (XML), not a JSON profile: name the file .xdd or .xdc")),
                           source=name, line=1)
    if looks_like == ".eds":
        raise ProfileError(Text(N_("this is an EDS/DCF (INI text), not a JSON profile: name the file .eds or .dcf")),
                           source=name, line=1)
    try:
        reject_duplicate_keys(content)
        profile = Profile.model_validate_json(content)
        return LoadedFile(profile, [ImportWarning(name, None, ref, Text(IGNORED_STILL, value=meaning))
                                    for ref, meaning in ignored_still_values(profile)])
    except DuplicateKey as exc:
        raise ProfileError(exc.args[0], source=name, line=exc.line) from exc
    except UnicodeDecodeError as exc:
        bad_line = content.count(b"\n", 0, exc.start) + 1
        raise ProfileError(Text(N_("not UTF-8 text")), source=name, line=bad_line) from exc
    except ValidationError as exc:
        first = exc.errors()[0]
        if first["type"] == "json_invalid":
            line = _json_error_line(content)
            raise ProfileError(Text(N_("not valid JSON: {reason}"), reason=first["msg"]), source=name,
                               line=line) from exc
        path, line = _where(content, tuple(first["loc"]))
        where = ".".join(str(part) for part in path)
        error = first.get("ctx", {}).get("error")  # a validator's ValueError (its Text); else pydantic's words
        reason = error.args[0] if isinstance(error, ValueError) and error.args and isinstance(error.args[0], str) \
            else first["msg"].removeprefix("Value error, ")
        if exc.error_count() > 1:
            reason = Text(N_("{reason} (and {count} more)"), reason=reason, count=exc.error_count() - 1)
        raise ProfileError(Text.joined(": ", [where, reason]) if where else reason, source=name, line=line) from exc


def _looks_like(content: bytes) -> str | None:
    """'.json' or '.eds' when the first characters of a file say so (a JSON profile is an object)."""
    head = content[:4096].lstrip(b"\xef\xbb\xbf \t\r\n")
    if head.startswith(b"{"):
        return ".json"
    if head.startswith(b"<"):
        return ".xdd"
    first_line = head.split(b"\n", 1)[0].strip()
    if head.startswith(b";") or (first_line.startswith(b"[") and first_line.endswith(b"]")
                                 and first_line[1:2].isalpha()):
        return ".eds"
    return None


def _where(content: bytes, path: JsonPath) -> tuple[JsonPath, int | None]:
    """The path and line of a validation error. The model's uniqueness check has no path: the second of the
    two entries with the same address is the one named."""
    try:
        data, lines = value_lines(content.decode("utf-8-sig"))
    except ValueError:
        return path, None
    if not path and isinstance(data, dict):
        path = _duplicate_entry(data) or path
    return path, line_of(lines, path)


def _duplicate_entry(data: dict[str, Any]) -> JsonPath | None:
    checks: list[tuple[str, Any]] = [
        ("objects", lambda item: (lambda e: (e.index, e.subindex))(ObjectEntry.model_validate(item))),
        ("parameters", lambda item: (lambda p: (p.code.upper(), p.subcode))(Parameter.model_validate(item))),
    ]
    for field, address in checks:
        items = data.get(field)
        seen: set[Any] = set()
        for position, item in enumerate(items if isinstance(items, list) else []):
            try:
                key = address(item)
            except ValidationError:
                continue
            if key in seen:
                return (field, position)
            seen.add(key)
    return None


def _json_error_line(content: bytes) -> int | None:
    try:
        json.loads(content)
    except json.JSONDecodeError as exc:
        return exc.lineno
    except UnicodeDecodeError:
        return 1
    return None


Publish = Callable[[str | None, "LoadedFile | None", tuple[str, str] | None], None]


def _profile_files(directory: Path) -> list[Path]:
    """A directory's profile files in load order: JSON first (a JSON profile wins over its EDS twin)."""
    if not directory.is_dir():
        return []
    files = sorted(p for p in directory.iterdir() if p.suffix.lower() in PROFILE_SUFFIXES and p.is_file())
    files.sort(key=lambda p: p.suffix.lower() != ".json")
    return files


def _load_one(path: Path, cache: ParsedCache | None, used: set[str] | None, json_ids: set[str],
              taken: set[str]) -> tuple[str | None, LoadedFile | None, tuple[str, str] | None]:
    """One file: (profile id, the loaded file, None), (id, None, None) for an EDS whose JSON twin won, or an error."""
    try:
        loaded_file = _read_cached(path.read_bytes(), path.name, cache, used)
    except ProfileError as exc:
        return None, None, (path.name, exc.detail)
    except OSError as exc:
        return None, None, (path.name, Text(N_("cannot read: {reason}"), reason=exc.strerror))
    profile = loaded_file.profile
    if path.suffix.lower() != ".json" and profile.id in json_ids:
        return profile.id, None, None  # the JSON twin wins
    if profile.id in taken:
        return None, None, (path.name, Text(N_("profile id '{id}' is already used by another file"), id=profile.id))
    return profile.id, loaded_file, None


def _read_cached(content: bytes, name: str, cache: ParsedCache | None, used: set[str] | None) -> LoadedFile:
    """:func:`read_profile_file`, through ``cache`` when given (a file that does not load is not cached)."""
    if cache is None:
        return read_profile_file(content, name)
    key = ParsedCache.key(name, content)
    if used is not None:
        used.add(key)
    parsed = cache.read(key)
    if parsed is not None:
        return LoadedFile(parsed.profile, parsed.warnings, content if parsed.keeps_original else None, parsed.suffix)
    loaded = read_profile_file(content, name)
    cache.write(key, Parsed(loaded.profile, loaded.warnings, loaded.original is not None, loaded.suffix))
    return loaded


class ProfileRegistry:
    """Profiles by id. Loads on construction; ``reload()`` reads the directories again.

    With ``defer_uploads`` only the built-in profiles load on construction; :meth:`load_uploads` (blocking: a
    worker thread) then adds the stored uploads one by one while the server already answers (issue 33).
    ``upload_progress()`` says how far it is, ``uploads_done`` is set when it is through."""

    def __init__(self, profiles_dir: Path | None = None, user_profiles_dir: Path | None = None,
                 max_upload_bytes: int | None = None, *, defer_uploads: bool = False) -> None:
        self.profiles_dir = profiles_dir or settings.profiles_dir
        self.user_profiles_dir = user_profiles_dir or settings.user_profiles_dir
        self.max_upload_bytes = max_upload_bytes or settings.max_upload_bytes
        self._profiles: dict[str, Profile] = {}
        self._files: dict[str, LoadedFile] = {}
        self._builtin: set[str] = set()
        self.errors: list[tuple[str, str]] = []
        self.uploads_done = threading.Event()
        self._stored = 0
        self._uploads_read = 0
        self._stop = threading.Event()
        self._begin = threading.Event()
        if defer_uploads:
            self._load_builtin()
        else:
            self.reload()

    def reload(self) -> None:
        """Read both directories again; the registry changes in one step when all is read."""
        files: dict[str, LoadedFile] = {}
        errors: list[tuple[str, str]] = []
        builtin = self._load_dir(_profile_files(self.profiles_dir), files, errors, taken=set())
        stored = self._read_uploads(files, errors, builtin, publish=None)
        self._profiles = {profile_id: loaded.profile for profile_id, loaded in files.items()}
        self._files, self._builtin, self.errors = files, builtin, errors
        self._stored = self._uploads_read = stored
        self.uploads_done.set()

    def _load_builtin(self) -> None:
        files: dict[str, LoadedFile] = {}
        errors: list[tuple[str, str]] = []
        builtin = self._load_dir(_profile_files(self.profiles_dir), files, errors, taken=set())
        self._profiles = {profile_id: loaded.profile for profile_id, loaded in files.items()}
        self._files, self._builtin, self.errors = files, builtin, errors
        self._stored, self._uploads_read = len(_profile_files(self.user_profiles_dir)), 0

    def begin_uploads(self) -> None:
        """Let :meth:`load_uploads` begin (a server start puts a large folder off until its first answer)."""
        self._begin.set()

    def load_uploads(self) -> None:
        """After ``defer_uploads``: add the stored uploads while the server answers, each profile as soon as it is
        read, once :meth:`begin_uploads` (or :meth:`stop_loading`) has been called (blocking: a worker thread)."""
        try:
            self._begin.wait()
            self._read_uploads({}, [], set(self._builtin), publish=self._publish)
        finally:
            self.uploads_done.set()

    def _publish(self, profile_id: str | None, loaded_file: LoadedFile | None, error: tuple[str, str] | None) -> None:
        # copy on write: the event loop iterates these while the loading thread adds to them
        if loaded_file is not None and profile_id is not None:
            self._files = {**self._files, profile_id: loaded_file}
            self._profiles = {**self._profiles, profile_id: loaded_file.profile}
        if error is not None:
            self.errors = [*self.errors, error]
        self._uploads_read += 1

    def _read_uploads(self, files: dict[str, LoadedFile], errors: list[tuple[str, str]], builtin: set[str],
                      publish: Publish | None) -> int:
        """The one place that reads the stored uploads, through the parsed cache; a file that does not load goes
        into ``errors``. Returns how many upload files there are."""
        cache = ParsedCache(self.user_profiles_dir)
        used: set[str] = set()
        paths = _profile_files(self.user_profiles_dir)
        self._stored = len(paths)
        self._load_dir(paths, files, errors, taken=set(builtin), cache=cache, used=used, publish=publish,
                       stop=self._stop)
        if not self._stop.is_set():
            cache.keep_only(used)
        return len(paths)

    def stop_loading(self) -> None:
        """Stop :meth:`load_uploads` after the file it reads (the server is shutting down)."""
        self._stop.set()
        self._begin.set()

    def upload_progress(self) -> tuple[int, int]:
        """(stored upload files read so far, stored upload files)."""
        return (self._stored if self.uploads_done.is_set() else min(self._uploads_read, self._stored)), self._stored

    @staticmethod
    def _load_dir(files: list[Path], profiles: dict[str, LoadedFile], errors: list[tuple[str, str]],
                  taken: set[str], cache: ParsedCache | None = None, used: set[str] | None = None,
                  publish: Publish | None = None, stop: threading.Event | None = None) -> set[str]:
        """Load profile files into ``profiles``: JSON first, then EDS/DCF without a JSON twin. With ``cache``, a
        file parsed before is taken from it (its keys go into ``used``). ``publish`` hears of each file as it is
        read (the profile or the error)."""
        loaded: set[str] = set()
        json_ids: set[str] = set()
        for path in files:
            if stop is not None and stop.is_set():
                break
            profile_id, loaded_file, error = _load_one(path, cache, used, json_ids, taken | loaded)
            if loaded_file is not None and profile_id is not None:
                if path.suffix.lower() == ".json":
                    json_ids.add(profile_id)
                profiles[profile_id] = loaded_file
                loaded.add(profile_id)
            if error is not None:
                errors.append(error)
            if publish is not None:
                publish(profile_id, loaded_file, error)
        return loaded

    def get(self, profile_id: str) -> Profile:
        try:
            return self._profiles[profile_id]
        except KeyError:
            raise UnknownProfile(Text(N_("No device profile '{id}'"), id=profile_id)) from None

    def has(self, profile_id: str) -> bool:
        return profile_id in self._profiles

    def loaded(self, profile_id: str) -> LoadedFile:
        """The profile with the warnings of its import and its file's bytes."""
        self.get(profile_id)
        return self._files.get(profile_id) or LoadedFile(self._profiles[profile_id])

    def all(self) -> list[Profile]:
        return sorted(self._profiles.values(), key=lambda p: p.id)

    def is_builtin(self, profile_id: str) -> bool:
        return profile_id in self._builtin

    def find_by_identity(self, vendor_id: int | None, product_code: int | None) -> Profile | None:
        """The profile for a scanned node's 0x1018 identity (built-in profiles first)."""
        matches = [p for p in self._profiles.values()
                   if p.identity.vendor_id == vendor_id and p.identity.product_code == product_code]
        matches.sort(key=lambda p: (p.id not in self._builtin, p.id))
        return matches[0] if matches else None

    def add_upload(self, filename: str, content: bytes) -> Profile:
        """Check and store an uploaded profile; the registry changes only if all of that succeeds.

        The stored file is named after the profile id (``<id>.eds``) in ``user_profiles_dir``; the uploaded
        file name is only shown (``uploaded_as``) and never becomes a path."""
        name = shown_name(filename)
        if len(content) > self.max_upload_bytes:
            raise ProfileError(Text(N_("upload is {size} bytes, more than the limit of {limit}"), size=len(content),
                                    limit=self.max_upload_bytes), source=name)
        loaded_file = read_profile_file(content, _load_name(name))
        profile = loaded_file.profile
        if profile.id in self._builtin:
            raise ProfileError(Text(N_("profile id '{id}' belongs to a built-in profile; give the upload another id"),
                                    id=profile.id), source=name)
        self._check_storable(profile.id, name)
        switch_clash = clash(profile, self._profiles.values())
        if switch_clash:
            raise ProfileError(switch_clash, source=name)
        suffix = Path(_load_name(name)).suffix.lower()
        target = self._stored_path(profile.id, suffix)
        self.user_profiles_dir.mkdir(parents=True, exist_ok=True)
        handle, temp = tempfile.mkstemp(dir=self.user_profiles_dir, prefix=".upload-")
        try:
            with os.fdopen(handle, "wb") as out:
                out.write(content)
            os.replace(temp, target)
        except OSError as exc:
            Path(temp).unlink(missing_ok=True)
            raise ProfileError(Text(N_("cannot store the upload: {reason}"), reason=exc.strerror), source=name) from exc
        for other in PROFILE_SUFFIXES:
            if other != suffix:
                self._stored_path(profile.id, other).unlink(missing_ok=True)
        self._profiles[profile.id] = profile
        self._files[profile.id] = loaded_file
        self._write_names({**self._read_names(), profile.id: name})
        return profile

    @staticmethod
    def _check_storable(profile_id: str, name: str) -> None:
        """The id becomes the stored file's name: short, and no name Windows keeps for a device."""
        if len(profile_id) > MAX_ID_CHARS:
            raise ProfileError(Text(N_("the profile id is {length} characters long; at most {limit} are allowed (it "
                                       "names the stored file)"), length=len(profile_id), limit=MAX_ID_CHARS),
                               source=name)
        if profile_id.split(".")[0] in WINDOWS_DEVICE_NAMES:
            raise ProfileError(Text(N_("the profile id '{id}' is a device name on Windows (CON, PRN, AUX, NUL, "
                                       "COM1-9, LPT1-9) and cannot name a file; rename the file or give the profile "
                                       "another id"), id=profile_id), source=name)

    def uploaded_as(self, profile_id: str) -> str | None:
        """The file name an uploaded profile came in as (None for built-in ones or when not recorded)."""
        return None if profile_id in self._builtin else self._read_names().get(profile_id)

    def _names_file(self) -> Path:
        return self.user_profiles_dir.with_name(self.user_profiles_dir.name + UPLOAD_NAMES_SUFFIX)

    def _read_names(self) -> dict[str, str]:
        try:
            names = json.loads(self._names_file().read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return {}
        return {str(k): str(v) for k, v in names.items()} if isinstance(names, dict) else {}

    def _write_names(self, names: dict[str, str]) -> None:
        with contextlib.suppress(OSError):  # only a name to show; the profile itself is stored
            text = json.dumps(names, ensure_ascii=False, indent=1, sort_keys=True)
            self._names_file().write_text(text, encoding="utf-8")

    def remove_upload(self, profile_id: str) -> None:
        """Delete the file(s) of an uploaded profile and read the directories again. Built-in ones stay."""
        self.get(profile_id)
        if profile_id in self._builtin:
            raise ProfileError(Text(N_("profile '{id}' is built in; only uploaded profiles can be deleted"),
                                    id=profile_id))
        directory = self.user_profiles_dir
        for path in sorted(directory.iterdir()) if directory.is_dir() else []:
            if path.suffix.lower() not in PROFILE_SUFFIXES or not path.is_file():
                continue
            if path.stem != profile_id:
                try:
                    if load_profile_file(path.read_bytes(), path.name).id != profile_id:
                        continue
                except (ProfileError, OSError):
                    continue
            path.unlink(missing_ok=True)
        names = self._read_names()
        if names.pop(profile_id, None) is not None:
            self._write_names(names)
        self.reload()

    def _stored_path(self, profile_id: str, suffix: str) -> Path:
        root = self.user_profiles_dir.resolve()
        target = (root / f"{profile_id}{suffix}").resolve()
        if target.parent != root:  # the id pattern forbids '/', this is a second fence
            raise ProfileError(Text(N_("profile id '{id}' is not a safe file name"), id=profile_id))
        return target

    @staticmethod
    def json_schema() -> dict[str, Any]:
        return Profile.model_json_schema()
