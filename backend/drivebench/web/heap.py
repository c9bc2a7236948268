"""The cyclic garbage collector of a long-running server (issue 21: the p99 of many clients).

Everything alive once the server has started (modules, profiles, the routes, the sessions' objects) lives until it
stops; without help every full collection walks all of it again: ~250,000 objects, one pass of 76 ms with the event
loop standing still during a run of benchmarks/request_path.py, and passes of the middle generation up to 4.5 ms
(benchmarks/RESULTS.md, Request path). :func:`settle` collects once and moves the survivors to the permanent
generation (``gc.freeze``), so later passes walk only what requests and frames made since. Reference counting still
frees every frozen object that is dropped; only a cycle among them would stay.

The youngest generation's threshold stays Python's (700): 5,000 made each pass seven times longer (0.8 ms) for the
same total.
"""

from __future__ import annotations

import gc


def hold() -> None:
    """Before start-up (``drivebench serve``, before its imports): no cyclic collection while modules, routes and
    profiles are made. The heap only grows then, and the passes over it freed next to nothing for a tenth of the
    start's CPU (issue 33); :func:`settle` collects once and turns collection on again."""
    gc.disable()


def settle() -> None:
    """After start-up: collect, freeze the survivors, collect from then on."""
    gc.collect()
    gc.freeze()
    gc.enable()
