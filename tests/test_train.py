"""The training loop: reproducibility, resume, SIGKILL, non-finite stops, the command line.

The reference is conftest's `trained_tiny`: the tiny config trained for its 4 steps without
interruption, built once per test run. The resumed and killed runs below are compared with it bit
for bit, which is also what "same config and seed, same parameters" means (two independent runs
of one seed)."""

import json
import os
import signal
import subprocess
import sys
import time

import jax
import numpy as np
import pytest
from conftest import assert_bit_identical, load_cli, run_cli

from motiongan_jax.config import override, to_dict
from motiongan_jax.data import sampling
from motiongan_jax.generate.preview import preview_curve, previewer
from motiongan_jax.model import apply as model_apply
from motiongan_jax.model import checkpoint, health
from motiongan_jax.motion import trajectory
from motiongan_jax.train import loop as train_lib


@pytest.fixture(scope="module")
def tiny(tiny_cfg):
    return tiny_cfg


@pytest.fixture(scope="module")
def unbroken(trained_tiny):
    return trained_tiny


def _params(workdir, step=None):
    state, meta, _, _ = checkpoint.load_run(workdir, step)
    return state, meta


def test_run_writes_metrics_checkpoints_and_lists(unbroken, tiny):
    wd = unbroken
    lines = [json.loads(x) for x in (wd / "metrics.jsonl").read_text().splitlines()]
    assert [r["step"] for r in lines] == [1, 2, 3, 4]
    for key in ("d_adv", "d_cls", "g_adv", "g_cls", "g_curve", "g_bone", "d_acc_real", "d_acc_fake",
                "g_grad_norm", "g_param_norm", "g_update_norm", "d_grad_norm"):
        assert key in lines[-1] and np.isfinite(lines[-1][key]), key
    assert sorted(int(p.name) for p in (wd / "checkpoints").iterdir() if p.name.isdigit()) == [2, 4]
    assert (wd / "train_files.txt").read_text().strip() and (wd / "val_files.txt").read_text().strip()
    state, meta = _params(wd)
    assert int(state.step) == 4 and meta["config"]["name"] == "tiny"


def test_other_seed_other_parameters(unbroken, tiny, tmp_path):
    train_lib.train(override(tiny, ["train.seed=1", "train.num_steps=2", "train.preview_every=2"]), tmp_path,
                    progress=False, log=lambda s: None, preview=previewer)
    gif = tmp_path / "previews" / "step_0000002.gif"
    assert gif.read_bytes()[:6] == b"GIF89a"
    a, _ = _params(unbroken, 2)
    b, _ = _params(tmp_path, 2)
    assert not np.array_equal(np.asarray(jax.tree.leaves(a.g_params)[0]), np.asarray(jax.tree.leaves(b.g_params)[0]))


def test_sigkill_and_restart_equals_unbroken(unbroken, repo, tmp_path):
    """Kill the command-line trainer with SIGKILL at several moments, restart it each time."""
    cmd = [sys.executable, str(repo / "bin" / "train.py"), "--config", str(repo / "configs" / "tiny.py"),
           "--workdir", str(tmp_path), "--no-progress", "--set", "train.checkpoint_every=1"]
    rng = np.random.default_rng(0)
    ckdir = tmp_path / "checkpoints"

    def latest():
        return max((int(p.name) for p in ckdir.iterdir() if p.name.isdigit()), default=0) if ckdir.is_dir() else 0

    for _ in range(2):
        before = latest()
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
        # once it has saved a new checkpoint, kill it at a random moment (often inside the next save)
        deadline = time.time() + 240
        while time.time() < deadline and latest() == before and proc.poll() is None:
            time.sleep(0.01)
        time.sleep(float(rng.uniform(0.0, 0.2)))
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr
    # checkpoint_every differs from the unbroken run: it changes nothing but when saves happen
    assert_bit_identical(_params(unbroken)[0], _params(tmp_path)[0])


def test_non_finite_stops_with_step_and_term(tiny, tmp_path, monkeypatch):
    real = sampling.make_sample_batch

    def poisoned(cfg, batch_size, rec_rows=0):
        sample = real(cfg, batch_size, rec_rows)

        def sample_batch(arrays, key, step):
            batch = sample(arrays, key, step)
            bad = jax.numpy.where(step >= 2, jax.numpy.nan, 0.0)  # from the 3rd step on
            return {**batch, "curve_BxTx3": batch["curve_BxTx3"] + bad}

        return sample_batch

    monkeypatch.setattr(sampling, "make_sample_batch", poisoned)
    with pytest.raises(train_lib.NonFiniteError, match=r"step 3: .*g_curve"):
        train_lib.train(tiny, tmp_path, progress=False, log=lambda s: None)
    assert checkpoint.manager(tmp_path / "checkpoints").latest_step() == 2


def test_labels_keep_their_embeddings_and_g_follows_its_code_after_training(unbroken):
    """Label -> code -> output after training, one robust link at a time. After 4 steps the paper's
    tiny Latent Transform init leaves the labels' codes w only 10-360 float32 spacings apart (5 seeds)
    (|w| ~ 5e-4), so the labels' own effect on the output is float32 rounding on any CPU; what
    holds everywhere is that each label keeps its own embedding and that G follows its code."""
    state, meta = _params(unbroken)
    C, T = len(meta["style_names"]), meta["window_T"]
    emb_CxZ = np.asarray(state.g_params["latent"]["embed"])
    gap = min(np.abs(emb_CxZ[a] - emb_CxZ[b]).max() for a in range(C) for b in range(a))
    assert gap > 0.05 * np.abs(emb_CxZ).max(), gap  # random init, moved by 4 Adam steps of 2e-4 at most
    w_CxD = np.asarray(model_apply.style_codes(state, jax.numpy.arange(C)))
    # a step of 0.1 along w1 - w0 (the codes' spread in a longer run) moves the pose by 0.82-1.13 of
    # its size (5 seeds, SSE4.2 kernels), far from the 0.1 asked
    vel = trajectory.velocity(jax.numpy.asarray(preview_curve(T, 0.08))[None]).repeat(2, 0)
    u = (w_CxD[1] - w_CxD[0]) / np.linalg.norm(w_CxD[1] - w_CxD[0])
    _, pose = model_apply.g_apply(state, vel, jax.numpy.asarray(np.stack([w_CxD[0], w_CxD[0] + 0.1 * u])))
    diff = float(np.abs(pose[0] - pose[1]).mean() / np.abs(pose[0]).mean())
    assert diff > 0.1, diff


def test_command_line_errors(repo, tmp_path):
    base = ["--config", repo / "configs" / "tiny.py", "--workdir", tmp_path / "wd"]
    for extra, name in ((["--set", "data.frame_nums=60"], "data.frame_nums"),
                        (["--data", tmp_path / "missing"], "data.data_dir"),
                        (["--set", "model.nope=1"], "model.nope")):
        code, _, err = run_cli("train", base + extra)
        assert code == 2 and name in err, (extra, err)
    assert not (tmp_path / "wd").exists()


def test_incompatible_checkpoint_is_refused(unbroken, tiny, tmp_path):
    import shutil

    shutil.copytree(unbroken / "checkpoints", tmp_path / "checkpoints")
    with pytest.raises(checkpoint.CheckpointError, match="incompatible"):
        train_lib.train(override(tiny, ["model.base_channels=8", "train.num_steps=6"]), tmp_path, progress=False,
                        log=lambda s: None)


def test_compute_only_fields_do_not_make_a_checkpoint_incompatible(tiny):
    # the compute section chooses how the same parameters are computed: a run trained with one
    # may resume or be evaluated with the other; an architecture field still refuses
    meta = {"model": to_dict(tiny)["model"], "window_T": tiny.data.window_T}
    other = override(tiny, ["compute.conv_impl=xla", "compute.compute_dtype=bfloat16"])
    assert other.model == tiny.model
    checkpoint.check_compatible(meta, {"model": to_dict(other)["model"]}, "here")
    with pytest.raises(checkpoint.CheckpointError, match="its model is"):
        wider = to_dict(override(tiny, ["model.base_channels=8"]))["model"]
        checkpoint.check_compatible(meta, {"model": wider}, "here")
    # a checkpoint from before the walker section: its flat fields (all off: the paper's G, or only
    # some of them, absent ones off) load as model.walker; a run with another value is refused
    older = {k: v for k, v in meta["model"].items() if k != "walker"}
    checkpoint.check_compatible({"model": {**older, "g_frame": "world", "exact_bones": False}},
                                {"model": to_dict(tiny)["model"]}, "here")
    framed = to_dict(override(tiny, ["model.walker=default", "model.walker.output_prior=false",
                                     "model.walker.exact_bones=false", "model.walker.gait_phase=false",
                                     "model.walker.root_height=false", "model.walker.stride_speed=false"]))["model"]
    checkpoint.check_compatible({"model": {**older, "g_frame": "curve"}}, {"model": framed}, "here")
    with pytest.raises(checkpoint.CheckpointError, match="its model is"):
        checkpoint.check_compatible({"model": {**older, "g_frame": "world"}}, {"model": framed}, "here")


def test_dry_run_prints_parameter_counts(repo, tmp_path):
    code, out, err = run_cli("train", ["--config", repo / "configs" / "tiny.py", "--workdir", tmp_path / "wd",
                                       "--dry-run"])
    assert code == 0, err
    assert "generator" in out.lower() and "discriminator" in out.lower()
    assert not (tmp_path / "wd").exists()


def test_training_on_one_batch_makes_g_follow_its_curves(tiny, tmp_path, monkeypatch):
    """The loop (data, step, Adam) fed one batch over and over: G learns to walk its curves. (On
    fresh batches 100 tiny steps lower the curve loss by 0-40% depending on the seed, a trend the
    rounding of another CPU can undo; on one batch it falls ~500x.)"""
    real = sampling.make_sample_batch

    def first_batch_only(cfg, batch_size, rec_rows=0):
        sample = real(cfg, batch_size, rec_rows)
        return lambda arrays, key, step: sample(arrays, key, 0)

    monkeypatch.setattr(sampling, "make_sample_batch", first_batch_only)
    # G's learning rate is raised (2e-4 -> 1e-3) so that 100 tiny steps get there
    cfg = override(tiny, ["train.num_steps=100", "train.checkpoint_every=100", "train.batch_size=8",
                          "train.lr_g=1e-3"])
    train_lib.train(cfg, tmp_path, progress=False, log=lambda s: None)
    curve = [json.loads(x)["g_curve"] for x in (tmp_path / "metrics.jsonl").read_text().splitlines()]
    assert len(curve) == 100
    # step 1 is G at its init; the median shrugs off the few steps the GAN kicks G off the path.
    # Measured, 5 seeds x SSE4.2/AVX2: 1e-3-3e-3 x step 1; with train.w_g_curve=0, 2-11 x.
    assert np.median(curve[50:]) < 0.05 * curve[0], (curve[0], np.median(curve[50:]))


def test_dry_run_of_the_paper_config_needs_no_data(repo, capsys, tmp_path):
    """Without the CMU files the paper model is described from the config: CMU's hierarchy
    (28 kept joints, 81 rows) and its 28 styles give the paper's parameter counts."""
    cli = load_cli("train")
    wd = tmp_path / "wd"
    assert cli.main(["--config", str(repo / "configs" / "paper.py"), "--workdir", str(wd), "--dry-run"]) == 0
    out = capsys.readouterr().out
    assert "no data given: CMU's skeleton" in out and "28 styles of data.styles" in out
    assert "28 kept joints -> 81 rows" in out
    assert "generator: 16,156,164 parameters" in out and "discriminator: 2,702,173 parameters" in out
    assert cli.main(["--config", str(repo / "configs" / "bandai.py"), "--workdir", str(wd), "--dry-run"]) == 2
    assert "label rule 'bandai' takes its skeleton and styles from the files; pass --data" in capsys.readouterr().err
    # training still needs the data
    assert cli.main(["--config", str(repo / "configs" / "paper.py"), "--workdir", str(wd)]) == 2
    assert "needs a data directory" in capsys.readouterr().err
    assert not wd.exists()


def test_repeated_set_flags_all_apply(repo, capsys):
    """`--set a=1 --set b=2` applies both (the first was once silently dropped)."""
    cli = load_cli("train")
    base = ["--config", str(repo / "configs" / "tiny.py"), "--workdir", "unused", "--dry-run"]
    assert cli.main(base + ["--set", "data.frame_nums=60", "--set", "model.base_channels=4"]) == 2
    assert "data.frame_nums" in capsys.readouterr().err
    assert cli.main(base + ["--set", "model.base_channels=4", "model.time_kernel=4", "--set", "model.w_dim=8"]) == 2
    assert "model.time_kernel" in capsys.readouterr().err


def _log_records(acc_of_step, last=7000, every=50):
    return [{"step": s, "d_acc_real": acc_of_step(s), "d_acc_fake": acc_of_step(s)}
            for s in range(every, last + 1, every)]


def test_upsets_are_found_in_the_log_and_the_runs_model_is_the_checkpoint_clear_of_them():
    # healthy: D's accuracy wanders between 0.5 and 0.7
    assert health.upset_steps(_log_records(lambda s: 0.5 if s % 100 else 0.7), 7000) == []
    # D right on every batch from step 6900: the 150-step windows ending at 6900 and 6950 hold
    # 0.6, 0.6, 1 (0.73) and 0.6, 1, 1 (0.87); only the one ending at 7000 reaches 0.9
    late = health.upset_steps(_log_records(lambda s: 1.0 if s >= 6900 else 0.6), 7000)
    assert late == [7000]
    # G's moving average (decay 0.999) remembers 1000 steps: checkpoint 7000 holds the upset, 6000 not
    assert health.memory_steps(0.999) == 1000 and health.memory_steps(0.0) == health.WINDOW_STEPS
    assert health.model_step(range(1000, 7001, 1000), late, 1000) == 6000
    # an upset over steps 7450-7850 of 8000, over by the last checkpoint, is still in its memory
    spell = health.upset_steps(_log_records(lambda s: 1.0 if 7350 <= s <= 7850 else 0.6, last=8000), 8000)
    assert spell == list(range(7450, 7851, 50))  # (7250, 7400] holds 0.6, 1, 1; (7750, 7900] 1, 1, 0.6
    assert health.model_step(range(1000, 8001, 1000), spell, 1000) == 7000
    assert health.model_step([8000], spell, 1000) is None
    # D winning the warm-up (the first 30 %, 2100 steps) is no upset: the first window counted,
    # (1950, 2100], holds 1, 0.6, 0.6
    assert health.upset_steps(_log_records(lambda s: 1.0 if s <= 2000 else 0.6), 7000) == []
    # fewer than three records in a window are never enough, nor a window longer than the run
    assert health.upset_steps(_log_records(lambda s: 1.0, every=100), 7000) == []
    assert health.upset_steps(_log_records(lambda s: 1.0, last=100, every=1), 100) == []


def test_the_loop_warns_of_an_upset_and_generation_uses_the_checkpoint_before_it(tiny, tmp_path, monkeypatch,
                                                                               caplog):
    # windows of 3 steps after a warm-up of 3 (of 6) and any accuracy counts: steps 4, 5 and 6 are
    # upsets; without a moving average G remembers 3 steps, so only checkpoint 2 is clear of them
    monkeypatch.setattr(health, "WINDOW_STEPS", 3)
    monkeypatch.setattr(health, "WARMUP_FRACTION", 0.5)
    monkeypatch.setattr(health, "ACCURACY", 0.0)
    lines = []
    cfg = override(tiny, ["train.num_steps=6", "train.keep_checkpoints=3"])
    assert cfg.train.g_ema_decay == 0.0
    train_lib.train(cfg, tmp_path, progress=False, log=lines.append)
    warnings = [x for x in lines if x.startswith("warning: D upset the run")]
    assert len(warnings) == 1 and "up to step 4;" in warnings[0] and "checkpoint 4 remembers" in warnings[0] \
        and "model is now checkpoint 2" in warnings[0], warnings
    assert checkpoint.resolve_step(tmp_path) == 2 and "--step 6 to use it" in caplog.text
    assert checkpoint.resolve_step(tmp_path, 6) == 6
    assert int(checkpoint.load_run(tmp_path)[0].step) == 2
    # without the log there is nothing to go by: the latest checkpoint
    (tmp_path / "metrics.jsonl").unlink()
    assert checkpoint.resolve_step(tmp_path) == 6

