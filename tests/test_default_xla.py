"""Bit identity as users compile: the suite compiles with faster XLA options (conftest.FAST), users
with XLA's defaults; this file runs the resume test (a half-written checkpoint left behind, a
moving average of G carried over) in a process with XLA's defaults (its own file, so that the
test's worker is not the one that runs test_train.py)."""

import json
import os
import subprocess
import sys

DEFAULT_XLA_RESUME = """
import json, os, sys
import jax, numpy as np
import orbax.checkpoint as ocp
jax.config.update("jax_compilation_cache_dir", sys.argv[2])  # the 3 runs compile one program
jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
from motiongan_jax.config import override, tiny
from motiongan_jax.train.loop import train
wd, cfg = sys.argv[1], override(tiny(), ["train.g_ema_decay=0.5"])
train(cfg, wd + "/unbroken", progress=False, log=lambda s: None)
train(override(cfg, ["train.num_steps=2"]), wd + "/resumed", progress=False, log=lambda s: None)
# what a process killed inside a save leaves behind: orbax's temporary directory
partial = wd + "/resumed/checkpoints/3.orbax-checkpoint-tmp-1234567/state"
os.makedirs(partial)
with open(partial + "/garbage", "wb") as f:
    f.write(bytes(100))
logs = []
train(cfg, wd + "/resumed", progress=False, log=logs.append)
# the saved states as stored (no model rebuilt: nothing else compiles here)
a, b = (ocp.StandardCheckpointer().restore(os.path.abspath(wd + d + "/checkpoints/4/state"))
        for d in ("/unbroken", "/resumed"))
la, lb = jax.tree.leaves(a), jax.tree.leaves(b)
with open(wd + "/resumed/metrics.jsonl") as f:
    steps = [json.loads(line)["step"] for line in f]
print(json.dumps({"leaves": len(la), "equal": sum(np.array_equal(x, y) for x, y in zip(la, lb)),
                  "ema_leaves": len(jax.tree.leaves(a["g_ema_params"])),
                  "g_leaves": len(jax.tree.leaves(a["g_params"])), "logs": logs, "steps": steps,
                  "xla_flags": os.environ.get("XLA_FLAGS"),
                  "steps_compiled": sum(f.startswith("jit_keyed_step-") for f in os.listdir(sys.argv[2]))}))
"""


def test_resume_equals_unbroken_compiled_as_users_compile(tmp_path):
    """The suite compiles with faster XLA options (conftest.FAST); users compile with XLA's defaults.
    Resumed ≡ unbroken holds there: a process with no XLA_FLAGS trains the tiny config with a
    moving average of G 4 steps unbroken, and 2 steps, then (a half-written checkpoint of step 3
    left behind) 2 more resumed from step 2; every leaf of the two states is equal, the average's
    included, and each step is logged once. The resumed run's step program is the unbroken run's.
    (That the average never feeds back: test_step's moving-average test.)"""
    env = {k: v for k, v in os.environ.items() if k not in ("XLA_FLAGS", "JAX_COMPILATION_CACHE_DIR")}
    out = subprocess.run([sys.executable, "-c", DEFAULT_XLA_RESUME, str(tmp_path), str(tmp_path / "xla_cache")],
                         env=env, capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-2000:]
    result = json.loads(out.stdout.strip().splitlines()[-1])
    assert result["xla_flags"] is None
    assert result["leaves"] > 300 and result["equal"] == result["leaves"], result
    assert result["ema_leaves"] == result["g_leaves"] > 0, result  # the average is in the states compared
    assert any("resumed from checkpoint at step 2" in s for s in result["logs"]), result["logs"]
    assert result["steps"] == [1, 2, 3, 4], result
    # a resumed run's step is the fresh run's program (its state committed to the device as a
    # restored one is), so the three trainings compile it once and load it twice
    assert result["steps_compiled"] == 1, result
