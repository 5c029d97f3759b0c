"""Training as 2 processes (jax.distributed on 127.0.0.1, CPU backend with gloo collectives, one
device each) equals 1 process with 2 devices, only process 0 writes files, and a SIGKILLed
2-process run resumes to the same result.

Expected bit for bit: both runs draw the same global batch (every process samples all of it)
and run the same SPMD program over 2 devices; the gradient average over 2 devices is one float
addition, which is commutative, so the order the collectives add in cannot change it.
"""

import json
import os
import signal
import socket
import subprocess
import sys
import time

from conftest import assert_bit_identical

from motiongan_jax.model import checkpoint

# runs bin/train.py with an audit hook that records, on a descriptor opened before it, every
# path under the workdir (outside checkpoints/) that the process opens for writing, creates,
# renames onto or removes: what "this process wrote files" means
LAUNCH = r"""
import os, runpy, sys
train, workdir, audit = sys.argv[1:4]
fd = os.open(audit, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
root = os.path.abspath(workdir)
skip = os.path.join(root, "checkpoints")
WRITE = os.O_WRONLY | os.O_RDWR | os.O_CREAT | os.O_APPEND | os.O_TRUNC
def hook(event, args):
    if event == "open":
        path, mode, flags = args
        by_mode = isinstance(mode, str) and any(c in mode for c in "wax+")
        if not (by_mode or (isinstance(flags, int) and flags & WRITE)):
            return
    elif event in ("os.rename", "os.replace"):
        path = args[1]
    elif event in ("os.mkdir", "os.remove", "os.rmdir", "shutil.rmtree", "os.truncate"):
        path = args[0]
    else:
        return
    if isinstance(path, int) or path is None:
        return
    p = os.path.abspath(os.fsdecode(path))
    if (p == root or p.startswith(root + os.sep)) and not (p == skip or p.startswith(skip + os.sep)):
        os.write(fd, f"{event} {p}\n".encode())
sys.addaudithook(hook)
sys.argv = [train] + sys.argv[4:]
runpy.run_path(train, run_name="__main__")
"""


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _start_pair(repo, workdir, audit_dir, tag, env):
    port = _free_port()
    procs = []
    for pid in (0, 1):
        cmd = [sys.executable, "-c", LAUNCH, str(repo / "bin" / "train.py"), str(workdir),
               str(audit_dir / f"{tag}_{pid}.txt"), "--config", str(repo / "configs" / "tiny.py"),
               "--workdir", str(workdir), "--no-progress", "--coordinator", f"127.0.0.1:{port}",
               "--num-processes", "2", "--process-id", str(pid)]
        # output to files: a full pipe nobody reads would stall one process and with it the other
        with open(audit_dir / f"{tag}_{pid}.out", "w") as out, open(audit_dir / f"{tag}_{pid}.err", "w") as err:
            procs.append(subprocess.Popen(cmd, stdout=out, stderr=err, env=env, start_new_session=True))
        procs[-1].logs = (audit_dir / f"{tag}_{pid}.out", audit_dir / f"{tag}_{pid}.err")
    return procs


def _finish(procs, timeout=1800):
    """(stdout, stderr) of each process once all have exited with status 0."""
    try:
        for p in procs:
            p.wait(timeout=timeout)
    finally:
        for p in procs:
            if p.poll() is None:
                os.killpg(p.pid, signal.SIGKILL)
                p.wait()
    outs = [(p.logs[0].read_text(), p.logs[1].read_text()) for p in procs]
    for p, (out, err) in zip(procs, outs):
        assert p.returncode == 0, err[-3000:]
    return outs


def test_two_processes_equal_one_with_two_devices_and_resume_after_sigkill(repo, tmp_path):
    env = {**os.environ, "JAX_PLATFORMS": "cpu"}  # the compilation cache and data cache of conftest
    ref_dir, run_dir, audit = tmp_path / "one_process", tmp_path / "two_processes", tmp_path / "audit"
    audit.mkdir()
    # the reference: one process, two forced CPU devices; the tiny config's 4 steps, checkpoints at 2 and 4
    ref = subprocess.run([sys.executable, str(repo / "bin" / "train.py"), "--config", str(repo / "configs" / "tiny.py"),
                          "--workdir", str(ref_dir), "--no-progress"], capture_output=True, text=True, timeout=1800,
                         env={**env,
                              "XLA_FLAGS": f"{env.get('XLA_FLAGS', '')} --xla_force_host_platform_device_count=2"})
    assert ref.returncode == 0, ref.stderr[-3000:]
    assert "data parallel over 2 devices in 1 process(es)" in ref.stdout

    # two processes, one device each: killed (SIGKILL, both) as soon as step 2 is saved, then
    # started again
    procs = _start_pair(repo, run_dir, audit, "killed", env)
    ckdir = run_dir / "checkpoints"
    deadline = time.time() + 1800
    while time.time() < deadline and not (ckdir / "2").is_dir() and all(p.poll() is None for p in procs):
        time.sleep(0.005)
    for p in procs:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
        p.wait()
    assert (ckdir / "2").is_dir(), procs[0].logs[1].read_text()[-3000:]
    # the 2-process run up to step 2 is the 1-process 2-device run, bit for bit
    assert_bit_identical(checkpoint.load_run(ref_dir, 2, params="raw")[0],
                          checkpoint.load_run(run_dir, 2, params="raw")[0])

    (out0, _), (out1, _) = _finish(_start_pair(repo, run_dir, audit, "resumed", env))
    assert "resumed from checkpoint at step 2" in out0, out0
    # process 1 prints nothing of its own (gloo's C++ layer announces each rank's connection)
    assert "done:" in out0 and [line for line in out1.splitlines() if not line.startswith("[Gloo]")] == [], out1
    # ... and after the kill and resume, still that run at step 4
    assert_bit_identical(checkpoint.load_run(ref_dir, 4, params="raw")[0],
                          checkpoint.load_run(run_dir, 4, params="raw")[0])

    # one writer: process 0 wrote the config, file lists and metrics, process 1 nothing but its
    # share of the checkpoints (orbax's multi-process save)
    for tag in ("killed", "resumed"):
        written0 = (audit / f"{tag}_0.txt").read_text()
        assert all(f"{run_dir / name}\n" in written0 for name in ("config.json", "train_files.txt", "val_files.txt")), \
            written0
        assert (audit / f"{tag}_1.txt").read_text() == ""
    assert str(run_dir / "metrics.jsonl") in (audit / "resumed_0.txt").read_text()
    steps = [json.loads(line)["step"] for line in (run_dir / "metrics.jsonl").read_text().splitlines()]
    assert steps == [1, 2, 3, 4]  # each step logged once, by one process
    shards = {p.name for p in (ckdir / "4" / "state").iterdir() if p.name.startswith("ocdbt.process_")}
    assert shards == {"ocdbt.process_0", "ocdbt.process_1"}  # both processes took part in the save
