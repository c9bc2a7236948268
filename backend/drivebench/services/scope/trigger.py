"""The scope's trigger: which samples of the running stream make a capture (pure, no bus, no clock).

* ``free``: every ``length`` samples make a capture, at once and again (a rolling view).
* ``single``: one capture around the first trigger, then the engine is done.
* ``normal``: a capture around each trigger; after one is complete the engine arms again.

A trigger is a level crossed on a channel (``rising``: the previous sample below or at the level, this one above;
``falling``: the other way; a status-word bit is a channel with its bit, level 0.5), or an event of the session
(an EMCY of any node, an NMT state change): the first sample at or after the event's time triggers. The engine
arms only once it holds the pre-trigger samples, so a capture always starts with ``pre`` samples before the
trigger sample, which is at position ``pre`` of the capture.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field
from typing import Literal

from drivebench.errors import InvalidValue
from drivebench.i18n import _
from drivebench.services.scope.source import ScopeEvent

Mode = Literal["free", "single", "normal"]
On = Literal["level", "emcy", "nmt"]
Edge = Literal["rising", "falling"]
Values = tuple[float | None, ...]


@dataclass(frozen=True)
class TriggerSpec:
    mode: Mode = "free"
    on: On = "level"
    channel: int = 0
    """The channel (position in the recording) whose level triggers."""
    edge: Edge = "rising"
    level: float = 0.0
    """In the channel's unit (the scaled value)."""
    pre_percent: float = 0.0
    length: int = 1000
    """Samples per capture."""
    node: int | None = None
    """EMCY / NMT: only this node's (None: any node of the session)."""

    def __post_init__(self) -> None:
        if not 0 <= self.pre_percent <= 100:
            raise InvalidValue(_("The pre-trigger is a share of the length from 0 to 100 %, not {value} %.").format(
                value=self.pre_percent))
        if self.length < 2:
            raise InvalidValue(_("A capture holds at least 2 samples, not {length}.").format(length=self.length))

    @property
    def pre(self) -> int:
        """Samples before the trigger sample."""
        return min(self.length - 1, round(self.length * self.pre_percent / 100))


@dataclass(frozen=True)
class Sample:
    sample: int
    time_s: float
    values: Values


@dataclass
class Capture:
    """Samples around one trigger (``trigger``: the trigger sample's position, None in free run)."""

    samples: list[Sample] = field(default_factory=list)
    trigger: int | None = None
    trigger_time_s: float | None = None

    @property
    def start_s(self) -> float | None:
        return self.samples[0].time_s if self.samples else None

    @property
    def end_s(self) -> float | None:
        return self.samples[-1].time_s if self.samples else None


class TriggerEngine:
    """Feed samples (and the session's events) in order; complete captures come back from :meth:`feed`."""

    def __init__(self, spec: TriggerSpec, channels: int) -> None:
        if spec.on == "level" and spec.mode != "free" and not 0 <= spec.channel < channels:
            raise InvalidValue(_("The trigger names channel {channel}; the recording has channels 1 to {count}.")
                               .format(channel=spec.channel + 1, count=channels))
        self.spec = spec
        self._before: deque[Sample] = deque(maxlen=max(1, spec.pre))
        self._previous: float | None = None
        self._event_at: float | None = None
        self.current: Capture | None = Capture() if spec.mode == "free" else None
        self.done = False
        self.captures = 0

    @property
    def armed(self) -> bool:
        return not self.done and self.current is None

    def event(self, event: ScopeEvent) -> None:
        """An EMCY or an NMT change: the trigger when the spec names its kind (and node), the engine is armed."""
        spec = self.spec
        if spec.on == "level" or spec.mode == "free" or not self.armed or self._event_at is not None:
            return
        if event.kind == spec.on and (spec.node is None or event.node == spec.node):
            self._event_at = event.time_s

    def feed(self, sample: Sample) -> Capture | None:
        """The next sample; the capture it completes, if any."""
        if self.done:
            return None
        if self.current is not None:
            return self._extend(sample)
        triggered = self._triggers(sample)
        if triggered and len(self._before) >= self.spec.pre:
            before = list(self._before)[-self.spec.pre:] if self.spec.pre else []
            self.current = Capture(before, len(before), sample.time_s)
            self._before.clear()
            self._event_at = None
            return self._extend(sample)
        if self.spec.pre:
            self._before.append(sample)
        return None

    def _triggers(self, sample: Sample) -> bool:
        spec = self.spec
        if spec.on != "level":
            return self._event_at is not None and sample.time_s >= self._event_at
        value = sample.values[spec.channel]
        previous, self._previous = self._previous, value
        if value is None or previous is None:
            return False
        if spec.edge == "rising":
            return previous <= spec.level < value
        return previous >= spec.level > value

    def _extend(self, sample: Sample) -> Capture | None:
        current = self.current
        assert current is not None
        current.samples.append(sample)
        if len(current.samples) < self.spec.length:
            return None
        self.captures += 1
        if self.spec.mode == "single":
            self.done = True
            self.current = current
        else:
            self.current = Capture() if self.spec.mode == "free" else None
            channel = self.spec.channel
            self._previous = sample.values[channel] if channel < len(sample.values) else None
        return current


def markers(events: list[ScopeEvent], capture: Capture) -> list[ScopeEvent]:
    """The events inside the capture's time span (a marker on its time axis)."""
    start, end = capture.start_s, capture.end_s
    if start is None or end is None:
        return []
    return [event for event in events if start <= event.time_s <= end]
