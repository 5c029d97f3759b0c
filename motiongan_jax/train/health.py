"""Has D won? A late upset read from the training log alone, without any evaluator.

A run that walks can fall over late: D starts to tell every fake window from every real one, G's
adversarial loss jumps and its walk degrades (docs/RESULTS.md §14, §16). The log shows it plainly:
D's batch accuracies on real and fake windows, well short of 1 in a healthy run once the first
steps are past, sit at 1 for hundreds of steps. `d_won_since` finds the first such span; the
training loop warns when it sees one and names the last checkpoint before it.
"""

from __future__ import annotations

from collections.abc import Sequence

WINDOW_STEPS = 500  # long enough that one lucky batch is no upset, short enough to flag it within a checkpoint
ACCURACY = 0.97  # D's mean accuracy (real and fake) over the window: right on nearly every batch
WARMUP_FRACTION = 0.2  # D wins the first steps of every run, while G has not learnt to walk yet


def d_won_since(records: Sequence[dict], num_steps: int) -> tuple[int, float] | None:
    """(step, accuracy) at the end of the first window of WINDOW_STEPS steps, after the warm-up
    (WARMUP_FRACTION of `num_steps`), over which the logged records' mean of d_acc_real and
    d_acc_fake is >= ACCURACY; None when there is none. `records` are metrics.jsonl's rows in
    step order; a window needs at least 3 of them."""
    steps = [int(r["step"]) for r in records]
    acc = [(float(r["d_acc_real"]) + float(r["d_acc_fake"])) / 2 for r in records]
    first_end = WARMUP_FRACTION * num_steps + WINDOW_STEPS
    lo = 0
    for hi, end in enumerate(steps):
        while steps[lo] <= end - WINDOW_STEPS:
            lo += 1
        n = hi - lo + 1
        if end >= first_end and n >= 3 and sum(acc[lo:hi + 1]) / n >= ACCURACY:
            return end, sum(acc[lo:hi + 1]) / n
    return None


def last_checkpoint_before(step: int, checkpoint_steps: Sequence[int]) -> int | None:
    """The latest of `checkpoint_steps` at or before `step` (None if all are later)."""
    before = [s for s in checkpoint_steps if s <= step]
    return max(before) if before else None
