# Two commands for a fresh machine: `make run` and `make test`.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
HOST ?= 127.0.0.1
PORT ?= 8000

.PHONY: help constraints run test test-quick bytecode install lint typecheck importlint pytest bench chromium postgresql nginx compose clean i18n-extract i18n-update i18n-compile

help:
	@echo "make run          serve http://$(HOST):$(PORT) with the built-in simulated plant"
	@echo "make test         ruff, mypy, lint-imports and the whole suite on PYTEST_WORKERS=$(PYTEST_WORKERS) workers (CI)"
	@echo "make test-quick   the suite without the tests marked slow (browser, faults, server processes,"
	@echo "                  long property runs): a developer's loop (CI runs them all)"
	@echo "make lint | typecheck | importlint | bench | constraints | i18n-update | i18n-compile | clean"

$(STAMP): pyproject.toml constraints.txt
	test -d $(VENV) || $(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -c constraints.txt -e '.[dev]'
	touch $(STAMP)

# Re-pin constraints.txt to what the venv holds now (after a pyproject.toml change: pip install -e '.[dev]' first).
constraints: $(STAMP)
	{ sed -n '1,3p' constraints.txt; $(BIN)/pip freeze --exclude-editable | grep -v '^drivebench'; } > constraints.txt.new
	mv constraints.txt.new constraints.txt

install: $(STAMP) i18n-compile

# Translations (Babel): extract the texts of the code and templates into the template catalogue, merge it into
# each language's .po (translate there: msgstr, no "#, fuzzy"), compile the .mo files the server reads.
LOCALE_DIR := backend/drivebench/locale
i18n-extract: $(STAMP)
	$(BIN)/pybabel --quiet extract -F babel.cfg --no-location --sort-output --width 120 \
		--project DriveBench --copyright-holder "DriveBench contributors" -o $(LOCALE_DIR)/messages.pot .

i18n-update: i18n-extract
	$(BIN)/pybabel --quiet update -i $(LOCALE_DIR)/messages.pot -d $(LOCALE_DIR) --width 120 --no-fuzzy-matching --ignore-obsolete

i18n-compile: $(STAMP)
	$(BIN)/pybabel compile --statistics -d $(LOCALE_DIR)

run: install
	$(BIN)/drivebench serve --host $(HOST) --port $(PORT) --demo

chromium:
	@command -v chromium >/dev/null 2>&1 || (apt-get update -qq && apt-get install -y -qq chromium >/dev/null)

lint: $(STAMP)
	$(BIN)/ruff check backend tests benchmarks

typecheck: $(STAMP)
	$(BIN)/mypy

importlint: $(STAMP)
	$(BIN)/lint-imports

# The suite starts a throw-away PostgreSQL cluster of its own (initdb/pg_ctl in a temp dir on a free port).
postgresql:
	@ls /usr/lib/postgresql/*/bin/initdb >/dev/null 2>&1 || (apt-get update -qq && apt-get install -y -qq postgresql >/dev/null)

# The sub-path test (tests/web/test_root_path_browser.py) puts Debian's nginx in front of a served DriveBench.
nginx:
	@command -v nginx >/dev/null 2>&1 || ls /usr/sbin/nginx >/dev/null 2>&1 || (apt-get update -qq && apt-get install -y -qq nginx >/dev/null)

# deploy/compose.yaml is checked with both Compose programs a plant runs (tests/test_container.py): Debian's
# docker-compose 1.29 and Compose v2, which Debian packages from trixie on (fetched, not installed: see the script).
COMPOSE_V2 := .cache/compose-v2/docker-compose

compose: $(COMPOSE_V2)
	@command -v docker-compose >/dev/null 2>&1 || (apt-get update -qq && apt-get install -y -qq docker-compose >/dev/null)

$(COMPOSE_V2):
	sh scripts/fetch_compose_v2.sh $@

# The suite runs on parallel workers (pytest-xdist), a module's tests on one worker (they share its fixtures).
# Most tests wait on a bus, a timeout or a browser, so more workers than cores pay: PYTEST_WORKERS=1 runs serially.
PYTEST_WORKERS ?= 4
PYTEST_PARALLEL := $(if $(filter-out 0 1,$(PYTEST_WORKERS)),-n $(PYTEST_WORKERS) --dist loadfile)

# Bytecode: where PYTHONDONTWRITEBYTECODE is set (as in a shared development container) every worker compiles every
# module it imports and pytest rewrites and compiles every test module anew, in every worker, on every run (about
# two thirds of a worker's collection). The suite runs with bytecode allowed: the package is compiled once before the
# workers start, and the first run leaves pytest's rewritten test modules in tests/**/__pycache__ (written
# atomically, so workers racing to write one are harmless) for every later run to load.
PYTEST_ENV := env -u PYTHONDONTWRITEBYTECODE

bytecode: $(STAMP)
	$(PYTEST_ENV) $(BIN)/python -m compileall -q backend

pytest: install chromium postgresql nginx compose bytecode
	$(PYTEST_ENV) $(BIN)/pytest $(PYTEST_PARALLEL)

# A developer's loop: the suite without the tests marked slow (browser tests, faults that wait out timeouts,
# server processes); `make test` and CI run them all.
# Six workers: the quick subset waits more than it computes (buses, sockets, timeouts), and on 2 quiet cores six
# workers took it from 3:15 (four) to 2:34 (README, "The suite as a working tool").
QUICK_WORKERS ?= 6
test-quick: install postgresql bytecode
	$(PYTEST_ENV) $(BIN)/pytest -n $(QUICK_WORKERS) --dist loadfile -m "not slow"

test: lint typecheck importlint pytest

bench: $(STAMP)
	$(BIN)/python benchmarks/run_all.py

clean:
	rm -rf $(VENV) .pytest_cache .mypy_cache .ruff_cache .cache
