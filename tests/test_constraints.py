"""Reproducible builds (issue 33): make, CI and the Dockerfile install with constraints.txt, which pins every package
the project names (its dependencies and extras) to one version; the image is installed without dev extras and
keeps no pip."""

from __future__ import annotations

import re
import tomllib

from packaging.requirements import Requirement
from packaging.utils import canonicalize_name

from drivebench.config import REPO_ROOT


def _pins() -> dict[str, str]:
    pins: dict[str, str] = {}
    for line in (REPO_ROOT / "constraints.txt").read_text(encoding="utf-8").splitlines():
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        name, sep, version = line.partition("==")
        assert sep and version, f"constraints.txt: {line!r} is not name==version"
        pins[canonicalize_name(name)] = version
    return pins


def test_every_named_package_is_pinned_to_a_version_it_allows() -> None:
    project = tomllib.loads((REPO_ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    named = [Requirement(text) for text in project["dependencies"]]
    named += [Requirement(text) for extra in project["optional-dependencies"].values() for text in extra]
    pins = _pins()
    assert {"psycopg-binary", "uvloop", "httptools"} <= set(pins), "what the extras pull in is pinned too"
    for requirement in named:
        name = canonicalize_name(requirement.name)
        assert name in pins, f"{requirement.name} is not pinned in constraints.txt"
        assert requirement.specifier.contains(pins[name], prereleases=True), (
            f"constraints.txt pins {requirement.name}=={pins[name]}, which pyproject.toml's {requirement} excludes")


def test_make_and_the_image_install_with_the_constraints_and_the_image_keeps_no_pip() -> None:
    makefile = (REPO_ROOT / "Makefile").read_text(encoding="utf-8")
    assert re.search(r"pip install .*-c constraints\.txt", makefile)
    dockerfile = (REPO_ROOT / "Dockerfile").read_text(encoding="utf-8")
    install = re.search(r"pip install (.*)", dockerfile)
    assert install and "--constraint constraints.txt" in install.group(1)
    assert "[dev]" not in dockerfile and "dev]" not in install.group(1), "the image installs dev tools"
    assert "pip uninstall --yes pip" in dockerfile
    before_install = dockerfile.split("pip install", 1)[0]
    assert "constraints.txt" in before_install, "constraints.txt is not copied before the install"
