"""The test suite never touches the repo's var/: its own database and upload folder, set here because this
package is imported before conftest.py imports drivebench.config."""

import os
import tempfile

_TEST_VAR = tempfile.mkdtemp(prefix="drivebench-tests-")
os.environ.setdefault("DRIVEBENCH_DATABASE_URL", f"sqlite:///{_TEST_VAR}/drivebench.db")
os.environ.setdefault("DRIVEBENCH_USER_PROFILES_DIR", f"{_TEST_VAR}/profiles")
