"""What every bench shares: the load average to print beside a figure, and a median timer."""

import os
import statistics
import time

import jax


def load() -> str:
    """The 1-, 5- and 15-minute load averages: the machine is shared, so every figure carries them."""
    return "load %.2f %.2f %.2f" % os.getloadavg()


def timed(fn, *args) -> float:
    """Wall seconds of one call of `fn(*args)`, its result waited for (JAX's asynchronous dispatch)."""
    t0 = time.perf_counter()
    jax.block_until_ready(fn(*args))
    return time.perf_counter() - t0


def median_time(fn, *args, repeats: int = 3) -> float:
    """Median wall seconds of `fn(*args)` after one untimed call (compilation, first touch)."""
    jax.block_until_ready(fn(*args))
    return statistics.median(timed(fn, *args) for _ in range(repeats))
