"""Data parallelism with jax.sharding: the same pure train_step over every local device.

A 1-D mesh over the devices ("data"); the batch is sharded along its first axis, the train state
(parameters, optimizer and spectral-norm state) is replicated. The step's math is unchanged: XLA
partitions the batch means and inserts the cross-device reductions, so the result equals the
single-device step on the same global batch up to the order of float additions.

Across hosts, `maybe_initialize_distributed()` calls `jax.distributed.initialize()` when the
standard variables are set (JAX_COORDINATOR_ADDRESS, JAX_NUM_PROCESSES, JAX_PROCESS_ID), after
which `jax.devices()` lists every host's devices and the same code runs unchanged; `bin/train.py`
calls it first. Not tested across real hosts (none available): every process would load the
data, sample the same global batch and write the same metrics and checkpoints.
"""

from __future__ import annotations

import os

import jax
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec as P


def maybe_initialize_distributed() -> bool:
    if os.environ.get("JAX_COORDINATOR_ADDRESS") and int(os.environ.get("JAX_NUM_PROCESSES", "1")) > 1:
        jax.distributed.initialize()
        return True
    return False


def data_mesh(devices=None) -> Mesh:
    devices = jax.devices() if devices is None else devices
    return Mesh(np.asarray(devices), ("data",))


def replicated(mesh: Mesh) -> NamedSharding:
    return NamedSharding(mesh, P())


def batch_sharded(mesh: Mesh) -> NamedSharding:
    return NamedSharding(mesh, P("data"))


def shard_step(train_step, mesh: Mesh, batch_size: int):
    """jit `train_step(state, batch, key)` with the batch split over the mesh's devices."""
    n = mesh.devices.size
    if batch_size % n:
        raise ValueError(f"train.batch_size {batch_size} is not divisible by the {n} devices")
    rep, shard = replicated(mesh), batch_sharded(mesh)
    return jax.jit(train_step, in_shardings=(rep, shard, rep), out_shardings=(rep, rep), donate_argnums=0)


def put_state(state, mesh: Mesh):
    return jax.device_put(state, replicated(mesh))


def put_batch(batch, mesh: Mesh):
    return jax.device_put(batch, batch_sharded(mesh))
