"""Upsets of the adversarial balance, read from the training log alone, and the run's model.

A run that walks can fall over late: for a while D tells nearly every fake window from every
real one, G's adversarial loss jumps and its walk degrades, and G's moving average carries the
broken weights for about 1 / (1 - decay) steps after (docs/RESULTS.md §14, §16, §17). The log
shows it plainly: D's batch accuracies on real and fake windows, well short of 1 in a healthy run
once the first steps are past, sit near 1 for a few records in a row. `upset_steps` finds the
logged steps where that holds; `model_step` picks the run's model, the latest checkpoint with
no upset in the steps its parameters remember. No evaluator is involved.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

WINDOW_STEPS = 150  # three records at the small presets' log_every: one lucky batch is no upset
ACCURACY = 0.9  # D's mean accuracy (real and fake) over the window: right on nearly every batch
WARMUP_FRACTION = 0.3  # D wins spells of the first 2,000-odd steps, while G learns to walk


def read_log(workdir) -> list[dict]:
    """metrics.jsonl's records in step order ([] when the run has no log)."""
    path = Path(workdir) / "metrics.jsonl"
    if not path.is_file():
        return []
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]


def upset_steps(records: Sequence[dict], num_steps: int) -> list[int]:
    """The logged steps after the warm-up (WARMUP_FRACTION of `num_steps`) at which the mean of
    d_acc_real and d_acc_fake over the records of the last WINDOW_STEPS steps is >= ACCURACY.
    `records` are metrics.jsonl's rows in step order; a window lies wholly inside the run and
    needs at least 3 of them."""
    steps = [int(r["step"]) for r in records]
    acc = [(float(r["d_acc_real"]) + float(r["d_acc_fake"])) / 2 for r in records]
    first = max(WARMUP_FRACTION * num_steps, WINDOW_STEPS)
    found, lo = [], 0
    for hi, end in enumerate(steps):
        while steps[lo] <= end - WINDOW_STEPS:
            lo += 1
        n = hi - lo + 1
        if end > first and n >= 3 and sum(acc[lo:hi + 1]) / n >= ACCURACY:
            found.append(end)
    return found


def memory_steps(g_ema_decay: float) -> int:
    """How far back a checkpoint's G remembers: the moving average's time constant, or one
    window without an average."""
    return round(1 / (1 - g_ema_decay)) if g_ema_decay > 0 else WINDOW_STEPS


def assess(records: Sequence[dict], checkpoint_steps: Sequence[int], num_steps: int,
           g_ema_decay: float) -> tuple[int | None, list[int]]:
    """(the run's model, `model_step`; the upsets the newest of `checkpoint_steps` remembers)
    from metrics.jsonl's `records` of a run of `num_steps` with G's moving average `g_ema_decay`."""
    upsets = upset_steps(records, num_steps)
    memory = memory_steps(g_ema_decay)
    newest = max(checkpoint_steps)
    return model_step(checkpoint_steps, upsets, memory), [u for u in upsets if newest - memory < u <= newest]


def model_step(checkpoint_steps: Sequence[int], upsets: Sequence[int], memory: int) -> int | None:
    """The latest of `checkpoint_steps` with no upset in the `memory` steps up to it; None when
    every checkpoint has one (or there are none)."""
    clear = [s for s in checkpoint_steps if not any(s - memory < u <= s for u in upsets)]
    return max(clear) if clear else None
