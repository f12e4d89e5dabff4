"""The one timing helper of every bench script: warm-up calls, then timed repeats, and their statistics.

    t = timed(lambda: sc.shadow_mask(mesh, light, points), repeats=5)   # one warm-up, then 5 timed calls
    t.median, t.min, t.runs, t.result                                   # seconds; the last call's return
    both = interleaved({"exact": run_exact, "volume": run_volume}, repeats=5)  # rounds: exact, volume, ...
    steps = timed_steps({"prepare": lambda _: sc.prepare(...), "query": lambda shadows: shadows.mask(p)}, 5)
    steps["prepare"].median, steps["query"].median, steps["total"].median
    seconds, result = clock(step)                                       # one call, for stateful sequences

Every figure a bench reports is a median of repeats after a warm-up, unless its script says otherwise
(a light path's frame keeps its fastest pass: the tracker's state makes frames differ, not noise).
Wall time by ``time.perf_counter``; callers that enqueue device work end their call with the queue
drained (the public calls do: they return host arrays or finish the queue).
"""

from __future__ import annotations

import statistics
import time
from dataclasses import dataclass, field
from typing import Any, Callable


@dataclass
class Timing:
    """Seconds of each timed call (warm-ups excluded), in call order, and the last call's result."""

    runs: list[float] = field(default_factory=list)
    result: Any = None

    @property
    def median(self) -> float:
        return statistics.median(self.runs)

    @property
    def min(self) -> float:
        return min(self.runs)

    @property
    def median_ms(self) -> float:
        return 1e3 * self.median


def clock(fn: Callable[[], Any]) -> tuple[float, Any]:
    """``(seconds, result)`` of one call of ``fn``."""
    start = time.perf_counter()
    result = fn()
    return time.perf_counter() - start, result


def timed(fn: Callable[[], Any], repeats: int, warmup: int = 1) -> Timing:
    """``warmup`` untimed calls of ``fn``, then ``repeats`` timed ones (at least one)."""
    return interleaved({None: fn}, repeats, warmup)[None]


def interleaved(fns: dict, repeats: int, warmup: int = 1, settle: float = 0.0) -> dict:
    """:func:`timed` for several callables at once, in rounds that call each in ``fns``' order, so that a
    shared machine's load drift hits all of them alike. ``settle`` seconds are slept before each timed
    call, so that one tool's worker threads, still spinning after its call, do not slow the next one.
    Returns ``{name: Timing}``."""
    for _ in range(warmup):
        for fn in fns.values():
            fn()
    timings = {name: Timing() for name in fns}
    for _ in range(max(repeats, 1)):
        for name, fn in fns.items():
            time.sleep(settle)
            seconds, timings[name].result = clock(fn)
            timings[name].runs.append(seconds)
    return timings


def timed_steps(steps: dict, repeats: int, warmup: int = 1) -> dict:
    """:func:`timed` for a call made of steps run in order, each given the previous step's result (the
    first gets None): ``{step: Timing}`` (each with its step's last result) plus ``"total"``, their sum
    run by run (with the last step's result)."""
    timings = {name: Timing() for name in steps}

    def run():
        result = None
        for name, step in steps.items():
            elapsed, result = clock(lambda: step(result))
            timings[name].runs.append(elapsed)
            timings[name].result = result
        return result

    total = timed(run, repeats, warmup)
    for timing in timings.values():
        del timing.runs[:warmup]                # the warm-ups are not timed
    timings["total"] = Timing([sum(runs) for runs in zip(*(t.runs for t in timings.values()))], total.result)
    return timings
