"""Checkpoints with orbax-checkpoint: atomic saves, the last K kept, self-describing metadata.

A checkpoint holds the train state (arrays only: PRNG keys are derived from the seed and the
step, never saved) and a JSON `meta` item: the config, the style names and the row layout, so
that generation and analysis can rebuild the model without the data. Orbax writes each step
into a temporary directory and renames it when complete, so a process killed mid-save leaves no
checkpoint that `latest_step` would pick up.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path

import jax
import numpy as np
import orbax.checkpoint as ocp

from motiongan_jax.config import from_dict
from motiongan_jax.model import health

_log = logging.getLogger(__name__)


class CheckpointError(RuntimeError):
    """Missing or incompatible checkpoint; the message says which and why."""


def manager(directory: str | Path, keep: int = 3) -> ocp.CheckpointManager:
    options = ocp.CheckpointManagerOptions(max_to_keep=keep, create=True, enable_async_checkpointing=False)
    return ocp.CheckpointManager(Path(directory).absolute(), options=options, item_names=("state", "meta"))


def save(mngr: ocp.CheckpointManager, step: int, state, meta: dict) -> None:
    mngr.save(step, args=ocp.args.Composite(state=ocp.args.StandardSave(state), meta=ocp.args.JsonSave(meta)))
    mngr.wait_until_finished()


def read_meta(mngr: ocp.CheckpointManager, step: int | None = None) -> tuple[int, dict]:
    step = mngr.latest_step() if step is None else step
    if step is None:
        raise CheckpointError(f"no checkpoint in {mngr.directory}")
    meta = mngr.restore(step, args=ocp.args.Composite(meta=ocp.args.JsonRestore()))["meta"]
    return step, meta


def restore(mngr: ocp.CheckpointManager, step: int, like_state):
    """Restore the state at `step` with the structure, shapes, dtypes and shardings of
    `like_state`; leaves without a sharding (jax.eval_shape's) go to this process's first device,
    so a checkpoint written by several devices or processes loads on one."""
    abstract = jax.tree.map(_target, like_state)
    try:
        return mngr.restore(step, args=ocp.args.Composite(state=ocp.args.StandardRestore(abstract)))["state"]
    except (ValueError, KeyError, TypeError) as err:
        raise CheckpointError(f"checkpoint {mngr.directory}/{step} does not fit this model: {err}") from err


def _target(leaf):
    target = ocp.utils.to_shape_dtype_struct(leaf)
    if getattr(target, "sharding", None) is None:
        target = jax.ShapeDtypeStruct(target.shape, target.dtype,
                                      sharding=jax.sharding.SingleDeviceSharding(jax.local_devices()[0]))
    return target


def check_compatible(meta: dict, expected: dict, where: str) -> None:
    """Refuse a checkpoint made for another skeleton, style list or architecture."""
    for key in ("style_names", "joint_names", "parents", "model", "window_T"):
        if key in expected and _architecture(key, meta.get(key)) != _architecture(key, expected[key]):
            raise CheckpointError(
                f"checkpoint in {where} is incompatible: its {key} is {meta.get(key)!r}, "
                f"this run needs {expected[key]!r}")


def _architecture(key: str, value):
    if key == "model" and isinstance(value, dict):
        # the model section whole, in this version's schema (config.upgrade), defaults filled in
        return from_dict({"model": value}).model
    return _jsonable(value)


def _jsonable(x):
    return json.loads(json.dumps(x, default=lambda o: o.tolist() if isinstance(o, np.ndarray) else str(o)))


def run_manager(workdir: str | Path) -> ocp.CheckpointManager:
    ckdir = Path(workdir) / "checkpoints"
    if not ckdir.is_dir():
        raise CheckpointError(f"no checkpoints in {workdir} (expected {ckdir})")
    return manager(ckdir)


def resolve_step(workdir: str | Path, step: int | None = None) -> int:
    """`step`, or by default the run's model: the latest checkpoint with no upset of D in the
    steps its G remembers (health.py, from metrics.jsonl). The latest checkpoint when the run has
    no log or every checkpoint follows an upset; a warning says when it is not the latest."""
    return _step_and_meta(run_manager(workdir), workdir, step)[0]


def _step_and_meta(mngr: ocp.CheckpointManager, workdir, step: int | None) -> tuple[int, dict]:
    latest, meta = read_meta(mngr, step)
    if step is not None:
        return latest, meta
    train = from_dict(meta["config"]).train
    chosen, recent = health.assess(health.read_log(workdir), mngr.all_steps(), train.num_steps, train.g_ema_decay)
    if chosen is None and recent:
        _log.warning(f"every checkpoint in {workdir} follows an upset of D (health.py); using the latest, {latest}")
    elif chosen is not None and chosen != latest:
        _log.warning(f"using checkpoint {chosen} of {workdir}: D upset the run at steps {recent[0]}-{recent[-1]}, "
                     f"which checkpoint {latest} remembers (health.py); --step {latest} to use it")
        return read_meta(mngr, chosen)
    return latest, meta


def load_run(workdir: str | Path, step: int | None = None, params: str = "ema"):
    """(state, meta, cfg, layout) of a training run's checkpoint, without its data: `step`, or by
    default the run's model (`resolve_step`). `params`: "ema" (default) puts G's moving average
    in `state.g_params` when the run keeps one (train.g_ema_decay > 0), "raw" leaves the trained
    parameters (model.state.inference_state)."""
    from motiongan_jax.model import state as model_state

    mngr = run_manager(workdir)
    step, meta = _step_and_meta(mngr, workdir, step)
    cfg, layout, like = abstract_model(meta)
    state = restore(mngr, step, like)
    return model_state.inference_state(state, params), meta, cfg, layout


def abstract_model(meta: dict):
    """(cfg, layout, abstract train state) that a checkpoint's (or an export's) meta describes:
    the state's shapes and dtypes (jax.ShapeDtypeStruct leaves) and its graph definitions."""
    from motiongan_jax.model import state as model_state
    from motiongan_jax.motion.representation import layout_from_parents

    cfg = from_dict(meta["config"])
    layout = layout_from_parents(meta["joint_names"], meta["parents"], meta["bone_lengths_m"],
                                 meta.get("rest_offsets_m"))
    like = jax.eval_shape(lambda: model_state.init_state(cfg, layout, len(meta["style_names"]), jax.random.key(0)))
    return cfg, layout, like
