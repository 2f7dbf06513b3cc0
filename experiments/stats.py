"""Summaries of timing samples: medians first (the machine is shared and noisy), then the tail."""

import cProfile
import io
import math
import pstats
import time


def percentile(samples: list[float], q: float) -> float | None:
    """The q-th percentile (0-100) with linear interpolation; None for no samples."""
    if not 0 <= q <= 100:
        raise ValueError(f"percentile: q must be within 0..100, got {q}")
    data = sorted(samples)
    if not data:
        return None
    rank = (len(data) - 1) * q / 100
    low, high = math.floor(rank), math.ceil(rank)
    return data[low] + (data[high] - data[low]) * (rank - low)


def summarize(samples: list[float], digits: int = 3) -> dict:
    """{n, p50, p90, p99, mean, min, max} of the samples, rounded; values None when there are none."""
    data = [float(s) for s in samples if s is not None]
    if not data:
        return {"n": 0, "p50": None, "p90": None, "p99": None, "mean": None, "min": None, "max": None}
    out = {"n": len(data), "mean": sum(data) / len(data), "min": min(data), "max": max(data)}
    out |= {f"p{q}": percentile(data, q) for q in (50, 90, 99)}
    return {k: (round(v, digits) if isinstance(v, float) else v) for k, v in out.items()}


def p50_p99(samples: list[float], digits: int = 3) -> dict:
    """Just the median and the 99th percentile, as summary.json wants them."""
    s = summarize(samples, digits)
    return {"p50": s["p50"], "p99": s["p99"]}


def profile_calls(call, calls: int) -> tuple[float, str]:
    """Run call() once to warm it up, then `calls` times under cProfile: (ms per call, the top 20 by cumulative)."""
    call()  # links open once, as in a running portal
    prof = cProfile.Profile()
    t0 = time.perf_counter()
    prof.enable()
    for _ in range(calls):
        call()
    prof.disable()
    per_call = (time.perf_counter() - t0) * 1000 / calls
    text = io.StringIO()
    pstats.Stats(prof, stream=text).sort_stats("cumulative").print_stats(20)
    return per_call, "\n".join(line for line in text.getvalue().splitlines() if line.strip())
