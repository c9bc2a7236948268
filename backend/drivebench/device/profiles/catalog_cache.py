"""The one home of what is derived from a loaded profile: its :class:`Catalog` (search, refs, groups), built once per
profile object and kept for the most recently used profiles only.

Entries are keyed by the profile object itself, not by its id string (an upload that replaces a profile brings a
new object with the same id: it gets a fresh catalogue) and not by ``id(profile)`` alone (an address can be reused
once a profile is freed): the key holds the profile, so its address cannot be reused while the entry lives.
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Callable
from typing import Generic, TypeVar

from drivebench.device.profiles.catalog import Catalog
from drivebench.device.profiles.profile import Profile

CACHE_SIZE = 64
"""Profiles whose derived data is kept (the built-in ones, a plant's uploads, the ones being browsed)."""

T = TypeVar("T")


class _Same:
    """A dictionary key that is one profile object (compared by identity: profiles are not hashable)."""

    __slots__ = ("profile",)

    def __init__(self, profile: Profile) -> None:
        self.profile = profile

    def __hash__(self) -> int:
        return id(self.profile)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, _Same) and other.profile is self.profile


class ProfileCache(Generic[T]):
    """``build(profile)`` once per profile object, for the ``size`` most recently used profiles (thread-safe: the
    profiles API builds catalogues in worker threads)."""

    def __init__(self, build: Callable[[Profile], T], size: int = CACHE_SIZE) -> None:
        self._build = build
        self.size = size
        self._entries: OrderedDict[_Same, T] = OrderedDict()
        self._lock = threading.Lock()

    def __call__(self, profile: Profile) -> T:
        key = _Same(profile)
        with self._lock:
            if key in self._entries:
                self._entries.move_to_end(key)
                return self._entries[key]
        built = self._build(profile)
        with self._lock:
            if key in self._entries:  # another thread built it meanwhile: everyone gets the same one
                return self._entries[key]
            self._entries[key] = built
            while len(self._entries) > self.size:
                self._entries.popitem(last=False)
        return built

    def __len__(self) -> int:
        return len(self._entries)


catalog_for: ProfileCache[Catalog] = ProfileCache(Catalog)
"""The profile's catalogue: sessions' nodes, parameter sets, the profiles API and drive words all take it here."""
