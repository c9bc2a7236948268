"""The scope's trigger engine (issue 31 item 3): edges, pre-trigger, single / normal / free run, event triggers,
markers."""

from __future__ import annotations

import pytest

from drivebench.errors import InvalidValue
from drivebench.services.scope.source import ScopeEvent
from drivebench.services.scope.trigger import Capture, Sample, TriggerEngine, TriggerSpec, markers


def _feed(engine: TriggerEngine, values: list[float | None], period: float = 0.01) -> list[Capture]:
    done = []
    for n, value in enumerate(values):
        capture = engine.feed(Sample(n, n * period, (value, 0.0)))
        if capture is not None:
            done.append(capture)
    return done


def test_rising_edge_with_pre_trigger_puts_the_first_sample_above_the_level_after_the_pre_samples() -> None:
    ramp = [float(v) for v in range(0, 1000, 50)]  # 0, 50 ... 950
    engine = TriggerEngine(TriggerSpec("single", "level", 0, "rising", 500, pre_percent=20, length=10), 2)
    [capture] = _feed(engine, ramp)
    assert capture.trigger == 2 and len(capture.samples) == 10
    values = [s.values[0] for s in capture.samples]
    assert values[capture.trigger] == 550.0, "the first sample above 500, not 500 itself"
    assert values[:2] == [450.0, 500.0]
    assert engine.done and _feed(engine, ramp) == []


def test_the_engine_arms_only_once_it_holds_the_pre_trigger_samples() -> None:
    # crosses 500 at sample 1, while 5 pre-trigger samples are asked: that crossing does not count
    values = [0.0, 600.0, 0.0, 0.0, 0.0, 0.0, 0.0, 600.0, 600.0, 600.0, 600.0, 600.0, 600.0]
    engine = TriggerEngine(TriggerSpec("single", "level", 0, "rising", 500, pre_percent=50, length=10), 2)
    [capture] = _feed(engine, values)
    assert capture.trigger == 5 and capture.samples[5].sample == 7


def test_falling_edge_and_no_pre_trigger() -> None:
    engine = TriggerEngine(TriggerSpec("single", "level", 0, "falling", 1.0, length=3), 2)
    [capture] = _feed(engine, [2.0, 2.0, 0.5, 0.0, 3.0, 0.0])
    assert capture.trigger == 0 and [s.sample for s in capture.samples] == [2, 3, 4]


def test_a_missing_value_is_no_edge() -> None:
    engine = TriggerEngine(TriggerSpec("single", "level", 0, "rising", 1.0, length=2), 2)
    assert _feed(engine, [0.0, None, 2.0, 0.0]) == []
    assert not engine.done


def test_normal_mode_captures_every_trigger_and_arms_again() -> None:
    square = [0.0, 0.0, 5.0, 5.0, 0.0, 0.0, 5.0, 5.0, 0.0, 0.0, 5.0, 5.0]
    engine = TriggerEngine(TriggerSpec("normal", "level", 0, "rising", 1.0, pre_percent=50, length=2), 2)
    captures = _feed(engine, square)
    assert [c.samples[c.trigger or 0].sample for c in captures] == [2, 6, 10]
    assert not engine.done and engine.captures == 3


def test_free_run_makes_a_capture_of_every_length_samples_without_a_trigger() -> None:
    engine = TriggerEngine(TriggerSpec("free", length=4), 2)
    captures = _feed(engine, [float(n) for n in range(10)])
    assert [[s.sample for s in c.samples] for c in captures] == [[0, 1, 2, 3], [4, 5, 6, 7]]
    assert all(c.trigger is None for c in captures)
    assert engine.current is not None and len(engine.current.samples) == 2


def test_an_emcy_of_the_named_node_triggers_at_the_next_sample() -> None:
    engine = TriggerEngine(TriggerSpec("single", "emcy", pre_percent=50, length=4, node=5), 2)
    assert _feed(engine, [0.0] * 3) == []
    engine.event(ScopeEvent(0.025, 3, "emcy", "EMCY 2310h"))  # another node: no trigger
    engine.event(ScopeEvent(0.025, 5, "nmt", "NMT Stopped"))  # another kind: no trigger
    assert engine.armed and engine.feed(Sample(3, 0.03, (0.0, 0.0))) is None
    engine.event(ScopeEvent(0.035, 5, "emcy", "EMCY 2310h"))
    captures = [c for n in range(4, 8) if (c := engine.feed(Sample(n, n * 0.01, (0.0, 0.0)))) is not None]
    assert [c.samples[c.trigger or 0].sample for c in captures] == [4]


def test_markers_are_the_events_inside_the_capture() -> None:
    engine = TriggerEngine(TriggerSpec("single", "level", 0, "rising", 0.5, length=3), 2)
    [capture] = _feed(engine, [0.0, 1.0, 1.0, 1.0, 1.0])
    events = [ScopeEvent(0.0, 3, "nmt", "before"), ScopeEvent(0.02, 3, "emcy", "inside"),
              ScopeEvent(0.5, 3, "emcy", "after")]
    assert [e.text for e in markers(events, capture)] == ["inside"]


@pytest.mark.parametrize(("spec", "channels"), [
    (dict(pre_percent=120.0), 2), (dict(length=1), 2), (dict(mode="single", channel=2), 2)])
def test_bad_settings_are_refused_in_words(spec: dict[str, object], channels: int) -> None:
    with pytest.raises(InvalidValue, match=r"\w+ \w+"):
        TriggerEngine(TriggerSpec(**spec), channels)  # type: ignore[arg-type]
