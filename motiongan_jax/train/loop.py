"""The training loop: data, the jitted step, logging, previews, checkpoints and resume.

Every random choice is a pure function of the seed and the step: the batch of step s comes from
fold_in(data_key, s) and the step's own key is fold_in(step_key, s). A run killed and resumed
from its latest checkpoint therefore repeats exactly what an unbroken run does.

With several devices the step runs data parallel (parallel.py), also across processes: every
process runs this loop; each draws the same global batch and feeds its devices their rows,
gradients are averaged across all devices, the state stays replicated. Process 0 alone writes
the config, the file lists, metrics, previews and the progress bar (and loads the data first, so
that only it fills the preprocessing cache); checkpoints are saved and restored by every process
together (orbax), so a killed multi-process run resumes like a single one.
"""

from __future__ import annotations

import json
import math
import sys
import time
from pathlib import Path

import jax
import numpy as np

from motiongan_jax import atomic
from motiongan_jax.config import Config, config_hash, to_dict
from motiongan_jax.data import clip_cache, file_labels, gait_stats, sampling
from motiongan_jax.model import checkpoint, health
from motiongan_jax.model import state as model_state
from motiongan_jax.train import objectives, parallel
from motiongan_jax.train import step as step_lib


class NonFiniteError(FloatingPointError):
    """A loss or gradient became NaN or infinite."""


# ----------------------------------------------------------------------------------------------
# set-up
# ----------------------------------------------------------------------------------------------

def run_meta(cfg: Config, dataset: clip_cache.Dataset) -> dict:
    """What a checkpoint must carry to be used without the data (and checked on resume)."""
    return {
        "config": to_dict(cfg),
        "config_hash": config_hash(cfg),
        "style_names": list(dataset.style_names),
        "joint_names": list(dataset.layout.joint_names),
        "parents": list(dataset.layout.parents),
        "bone_lengths_m": [float(x) for x in dataset.layout.bone_lengths_m],
        "rest_offsets_m": np.asarray(dataset.layout.rest_offsets_m).tolist(),
        "fps": dataset.fps,
        "model": to_dict(cfg)["model"],
        "window_T": cfg.data.window_T,
        "data_dir": dataset.data_dir,
    }


def keys(seed: int):
    base = jax.random.key(seed)
    k_init, k_data, k_step = jax.random.split(base, 3)
    return k_init, k_data, k_step


def _append_jsonl(path: Path, record: dict) -> None:
    with open(path, "a") as fh:
        fh.write(json.dumps(record) + "\n")


def _truncate_metrics(path: Path, last_step: int) -> None:
    """After a resume, drop records logged past the checkpoint (they will be logged again)."""
    if not path.exists():
        return
    keep = [line for line in path.read_text().splitlines() if line.strip() and json.loads(line)["step"] <= last_step]
    atomic.write_text(path, "".join(line + "\n" for line in keep))


class Progress:
    """A one-line progress bar on stderr: step, steps/s, ETA and the main losses."""

    def __init__(self, total: int, start: int, enabled: bool):
        self.total, self.start, self.enabled = total, start, enabled
        self.t0 = time.perf_counter()

    def update(self, step: int, metrics: dict) -> str:
        done = step - self.start
        rate = done / max(time.perf_counter() - self.t0, 1e-9)
        eta = (self.total - step) / rate if rate > 0 else float("inf")
        width = 24
        filled = int(width * step / self.total)
        losses = " ".join(f"{k}={metrics[k]:.3g}" for k in ("d_total", "g_adv", "g_cls", "g_curve", "g_bone")
                          if k in metrics)
        line = (f"[{'#' * filled}{'.' * (width - filled)}] {step}/{self.total} {rate:.2f} it/s "
                f"ETA {_hms(eta)} {losses}")
        if self.enabled:
            print(line, file=sys.stderr, flush=True)
        return line


def _hms(seconds: float) -> str:
    if not math.isfinite(seconds):
        return "?"
    s = int(seconds)
    return f"{s // 3600}:{s // 60 % 60:02d}:{s % 60:02d}"


# ----------------------------------------------------------------------------------------------
# the loop
# ----------------------------------------------------------------------------------------------

def make_step_fn(cfg: Config, dataset, log=print):
    """The pure `train_step(state, batch, key)` for this dataset, with the gait targets of its
    training clips when the config's gait terms need them."""
    gait = None
    if step_lib.needs_gait_targets(cfg.train):
        gait = gait_stats.gait_targets(dataset.train, dataset.style_names, dataset.layout,
                                       dataset.fps / cfg.data.frame_step)
        log(f"gait targets from the training clips: contact height {gait.contact_height_m * 100:.1f} cm; stride "
            + ", ".join(f"{n} {v:.2f} m at {s:.2f} m/s" for n, v, s in
                        zip(dataset.style_names, gait.stride_m_C, gait.speed_mps_C))
            + f"; log stride rises {gait.stride_speed_slope:.2f} x log speed within styles; step height "
            + ", ".join(f"{n} {h * 100:.1f} cm" for n, h in zip(dataset.style_names, gait.step_height_m_C)))
    return step_lib.make_train_step(cfg, dataset.layout, dataset.num_styles, gait)


def train(cfg: Config, workdir: str | Path, *, progress: bool = True, log=print, preview=None) -> dict:
    """Train (or resume) in `workdir`; returns the last logged metrics. In a multi-process run
    every process calls this; only process 0 logs and writes files (module doc). `preview(cfg,
    dataset)` (e.g. generate.preview.previewer) returns `write(path, state)`, called every
    train.preview_every steps with the path of that step's GIF: training itself never generates."""
    workdir = Path(workdir)
    primary = parallel.is_primary()
    if not primary:
        log, progress = (lambda *a, **k: None), False
    if primary:  # the others read the cache it fills
        workdir.mkdir(parents=True, exist_ok=True)
        dataset = clip_cache.load_dataset(cfg.data, log=log)
    parallel.sync("dataset")
    if not primary:
        dataset = clip_cache.load_dataset(cfg.data, log=log)
    meta = run_meta(cfg, dataset)
    if primary:
        file_labels.write_file_lists(workdir, [(c.source, c.label) for c in dataset.train],
                              [(c.source, c.label) for c in dataset.val])
        atomic.write_json(workdir / "config.json", meta)

    arrays = sampling.build_arrays(dataset.train, dataset.style_names, cfg.data)
    k_init, k_data, k_step = keys(cfg.train.seed)
    state = model_state.init_state(cfg, dataset.layout, dataset.num_styles, k_init)
    step_fn = make_step_fn(cfg, dataset, log)

    def keyed_step(state, batch, key, s):  # the step's key, fold_in(k_step, s), made on the device
        return step_fn(state, batch, jax.random.fold_in(key, s))

    # every process draws the whole batch on its first local device (parallel.py's module doc)
    sample_batch = jax.jit(sampling.make_sample_batch(cfg.data, cfg.train.batch_size,
                                                          objectives.reconstructed_rows(cfg.train)))
    parallel_run = jax.device_count() > 1
    if parallel_run:  # data parallel: batch split over the devices of every process, state replicated
        mesh = parallel.data_mesh()
        train_step = parallel.shard_step(keyed_step, mesh, cfg.train.batch_size, num_replicated=2)
        state = parallel.put_state(state, mesh)
        step_key = parallel.put_key(k_step, mesh)
        log(f"data parallel over {jax.device_count()} devices in {jax.process_count()} process(es)")
    else:
        train_step = jax.jit(keyed_step, donate_argnums=0)
        # committed to the device as a restored state is: a fresh run and a resumed one then
        # compile one program, which a resume finds in the compilation cache
        state = jax.device_put(state, jax.sharding.SingleDeviceSharding(jax.local_devices()[0]))
        step_key = k_step

    mngr = checkpoint.manager(workdir / "checkpoints", keep=cfg.train.keep_checkpoints)
    start = 0
    if mngr.latest_step() is not None:
        ck_step, ck_meta = checkpoint.read_meta(mngr)
        checkpoint.check_compatible(ck_meta, meta, str(workdir / "checkpoints"))
        state = checkpoint.restore(mngr, ck_step, state)  # into the state's own sharding
        start = ck_step
        log(f"resumed from checkpoint at step {start} in {workdir / 'checkpoints'}")
    if primary:
        _truncate_metrics(workdir / "metrics.jsonl", start)
    total = cfg.train.num_steps
    if start >= total:
        log(f"nothing to do: checkpoint step {start} >= train.num_steps {total}")
        return {}

    write_preview = preview(cfg, dataset) if preview is not None and primary and cfg.train.preview_every else None
    bar = Progress(total, start, progress)
    last: dict = {}
    pending = None  # (step, metrics) of the previous step, checked one step late to keep dispatch async
    warned = False  # an upset is reported once per call
    for s in range(start, total):
        batch = sample_batch(arrays, k_data, s)
        if parallel_run:
            batch = parallel.global_batch(batch, mesh)
        state, metrics = train_step(state, batch, step_key, s)
        if pending is not None:
            last = _check_and_log(pending, workdir, cfg, bar, primary)
        pending = (s + 1, metrics)
        done = s + 1
        if done % cfg.train.checkpoint_every == 0 or done == total:
            last = _check_and_log(pending, workdir, cfg, bar, primary, force=done == total)
            pending = None
            checkpoint.save(mngr, done, state, meta)  # every process: orbax writes it together
            if primary and not warned:
                warned = _warn_if_upset(workdir, cfg, mngr.all_steps(), log)
        if write_preview is not None and done % cfg.train.preview_every == 0:
            write_preview(workdir / "previews" / f"step_{done:07d}.gif", parallel.local_copy(state))
    if pending is not None:
        last = _check_and_log(pending, workdir, cfg, bar, primary, force=True)
    return last


def _warn_if_upset(workdir: Path, cfg: Config, checkpoint_steps, log) -> bool:
    """Log a warning when the newest checkpoint follows an upset of D (health.py), naming the
    checkpoint that generation, evaluation and export now use; True if it did."""
    chosen, recent = health.assess(health.read_log(workdir), checkpoint_steps, cfg.train.num_steps,
                                   cfg.train.g_ema_decay)
    if not recent:
        return False
    newest = max(checkpoint_steps)
    log(f"warning: D upset the run: it judged at least {health.ACCURACY:.0%} of the logged real and fake "
        f"windows right over the {health.WINDOW_STEPS} steps up to step {recent[0]}"
        + (f" (and up to {recent[-1]})" if len(recent) > 1 else "")
        + f"; G's checkpoint {newest} remembers it; "
        + (f"the run's model is now checkpoint {chosen} (generation, evaluation and export use it unless "
           f"given --step)" if chosen is not None else "no kept checkpoint is clear of it"))
    return True


def _check_and_log(pending, workdir: Path, cfg: Config, bar: Progress, primary: bool, force: bool = False) -> dict:
    """Every process checks (the metrics are replicated: all stop together); process 0 logs."""
    step, metrics = pending
    values = {k: float(v) for k, v in jax.device_get(metrics).items()}
    bad = [k for k, v in values.items() if not math.isfinite(v)]
    if bad:
        raise NonFiniteError(
            f"non-finite values at step {step}: {', '.join(bad)}; training stopped, "
            f"the latest checkpoint in {workdir / 'checkpoints'} is the last good one")
    if primary and (force or step % cfg.train.log_every == 0):
        record = {"step": step, **values}
        _append_jsonl(workdir / "metrics.jsonl", record)
        bar.update(step, values)
    return values
