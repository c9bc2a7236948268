"""The test suite never touches the repo's var/: its own database, upload folder and secret key, set here because
this package is imported before conftest.py imports drivebench.config.

Each process of a run has its own folder: under pytest-xdist the controller imports this package first and its
workers inherit its variables, so a worker replaces the ones the controller set (``DRIVEBENCH_TESTS_VAR`` names
that folder); variables a developer set before the run are kept."""

import atexit
import os
import shutil
import tempfile

_TEST_VAR = tempfile.mkdtemp(prefix=f"drivebench-tests-{os.environ.get('PYTEST_XDIST_WORKER', 'main')}-")
_INHERITED = os.environ.get("DRIVEBENCH_TESTS_VAR")
for _name, _value in {"DRIVEBENCH_DATABASE_URL": f"sqlite:///{_TEST_VAR}/drivebench.db",
                      "DRIVEBENCH_USER_PROFILES_DIR": f"{_TEST_VAR}/profiles",
                      "DRIVEBENCH_SECRET_KEY_FILE": f"{_TEST_VAR}/secret_key"}.items():
    if _name not in os.environ or (_INHERITED and _INHERITED in os.environ[_name]):
        os.environ[_name] = _value
os.environ["DRIVEBENCH_TESTS_VAR"] = _TEST_VAR
atexit.register(shutil.rmtree, _TEST_VAR, ignore_errors=True)
