"""Fuzz the whole REST API from its OpenAPI spec with many more cases than CI (`tests/web/test_fuzz_api.py`).

Same harness as the test: the real app with the demo plant in uvicorn, schema-valid and schema-invalid cases per
operation, random and aimed at the plant. Prints cases run, operations covered, answers by status and every
server error with a curl line to repeat it.

    .venv/bin/python benchmarks/fuzz_api.py                 # 50 examples per operation and mode
    .venv/bin/python benchmarks/fuzz_api.py --examples 200 --only /parameters
"""

from __future__ import annotations

import argparse
import logging
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the `tests` package, for the shared harness

from tests.web.test_fuzz_api import FuzzReport, fuzz_operation, operation_labels, running_api


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--examples", type=int, default=50, help="examples per operation and mode (CI: 3)")
    parser.add_argument("--only", default="", help="fuzz only operations whose 'METHOD /path' contains this")
    args = parser.parse_args()
    logging.getLogger("canopen").setLevel(logging.CRITICAL)  # each SDO timeout of a stopped node is a 504 here
    labels = [label for label in operation_labels() if args.only in label]
    total = FuzzReport()
    started = time.monotonic()
    with tempfile.TemporaryDirectory(prefix="drivebench-fuzz-") as work, running_api(Path(work)) as target:
        for label in labels:
            method, path = label.split(" ", 1)
            report = FuzzReport()
            operation_started = time.monotonic()
            fuzz_operation(target.schema[path][method], target, args.examples, report)
            seconds = time.monotonic() - operation_started
            print(f"{report.cases:5d} cases {report.server_errors():3d} 5xx {seconds:6.1f} s  {label}", flush=True)
            for failure in report.failures:
                print("      " + failure.replace("\n", "\n      "), flush=True)
            total.cases += report.cases
            total.statuses.update(report.statuses)
            total.failures += report.failures
            total.device_faults += report.device_faults
    statuses = ", ".join(f"{status}: {count}" for status, count in sorted(total.statuses.items(), key=str))
    print(f"\noperations covered: {len(labels)}\ncases run: {total.cases} in {time.monotonic() - started:.0f} s\n"
          f"answers by status: {statuses}\n"
          f"device/bus faults (502/503/504 problem+json): {total.device_faults}\n"
          f"server errors (5xx other than those, or no answer): {len(total.failures)}")
    return 1 if total.failures else 0


if __name__ == "__main__":
    raise SystemExit(main())
