"""Data parallelism with jax.sharding: the same pure train_step over every device of one process
or of several (JAX's multi-controller runtime, `jax.distributed`).

A 1-D mesh over every device of every process ("data"); the batch is sharded along its first
axis, the train state (parameters, optimizer and spectral-norm state) is replicated. The step's
math is unchanged: XLA partitions the batch means and inserts the cross-device reductions (the
gradient average), so the result equals the single-device step on the same global batch up to
the order of float additions.

The batch. Every process draws the whole global batch from the data key and the step, as a
single process does (`data.make_sample_batch` on its first local device), and gives the mesh
only the rows its own devices hold (`global_batch`). So the batch, and with it the training, is
the same for any split of the same number of devices into processes (1 process x 2 devices and 2
processes x 1 device train bit-identically, tests/test_multiprocess.py), a resumed run needs no
per-process data state, and no process waits for another's data. The price, each process
sampling B windows instead of B / N and holding the (small) clip arrays, is a few milliseconds
per step (docs/PERFORMANCE.md); it does not grow with the number of processes.

Several processes. `initialize_distributed` starts `jax.distributed` from flags or from the
environment (module doc of that function); afterwards `jax.devices()` lists every process's
devices and the same code runs. `is_primary()` is process 0, which alone writes files;
checkpoints are written by every process together (orbax).
"""

from __future__ import annotations

import os

import jax
import numpy as np
from jax.sharding import Mesh, NamedSharding
from jax.sharding import PartitionSpec as P


class DistributedError(ValueError):
    """Incomplete or inconsistent multi-process settings; the message says which."""


def initialize_distributed(coordinator: str | None = None, num_processes: int | None = None,
                           process_id: int | None = None) -> bool:
    """Start `jax.distributed` when this run is one of several processes; True if it did.

    - flags: coordinator ("host:port" of process 0), num_processes and process_id, all three;
    - else the environment: JAX_COORDINATOR_ADDRESS with JAX_NUM_PROCESSES and JAX_PROCESS_ID
      (jax itself reads the address, and JAX_LOCAL_DEVICE_IDS);
    - else a launcher that jax recognises on its own, when it started more than one process:
      SLURM's srun (SLURM_NTASKS > 1) or Open MPI's mpirun (OMPI_COMM_WORLD_SIZE > 1).
    Nothing else starts it: a single process never waits for peers.
    """
    given = [v is not None for v in (coordinator, num_processes, process_id)]
    if any(given) and not all(given):
        raise DistributedError("--coordinator, --num-processes and --process-id go together")
    env = os.environ
    if not any(given) and env.get("JAX_COORDINATOR_ADDRESS"):
        missing = [k for k in ("JAX_NUM_PROCESSES", "JAX_PROCESS_ID") if not env.get(k)]
        if missing:
            raise DistributedError(f"JAX_COORDINATOR_ADDRESS is set but {' and '.join(missing)} not")
        coordinator = env["JAX_COORDINATOR_ADDRESS"]
        num_processes, process_id = _int(env["JAX_NUM_PROCESSES"], "JAX_NUM_PROCESSES"), \
            _int(env["JAX_PROCESS_ID"], "JAX_PROCESS_ID")
    if coordinator is not None:
        if not 0 <= process_id < num_processes:
            raise DistributedError(f"process id {process_id} is not in 0..{num_processes - 1}")
        if num_processes == 1:
            return False
        jax.distributed.initialize(coordinator, num_processes, process_id)
        return True
    if _int(env.get("SLURM_NTASKS", "1"), "SLURM_NTASKS") > 1 and "SLURM_PROCID" in env or \
            _int(env.get("OMPI_COMM_WORLD_SIZE", "1"), "OMPI_COMM_WORLD_SIZE") > 1:
        jax.distributed.initialize()  # jax reads the launcher's variables
        return True
    return False


def _int(text: str, what: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise DistributedError(f"{what} must be an integer, got {text!r}") from None


def is_primary() -> bool:
    """Process 0: the one that writes metrics, previews, the config and file lists."""
    return jax.process_index() == 0


def sync(name: str) -> None:
    """Wait until every process reaches the point called `name` (no-op for one process)."""
    if jax.process_count() > 1:
        from jax.experimental import multihost_utils

        multihost_utils.sync_global_devices(name)


def data_mesh(devices=None) -> Mesh:
    devices = jax.devices() if devices is None else devices
    return Mesh(np.asarray(devices), ("data",))


def replicated(mesh: Mesh) -> NamedSharding:
    return NamedSharding(mesh, P())


def batch_sharded(mesh: Mesh) -> NamedSharding:
    return NamedSharding(mesh, P("data"))


def shard_step(train_step, mesh: Mesh, batch_size: int, num_replicated: int = 1):
    """jit `train_step(state, batch, *args)` with the batch split over the mesh's devices and the
    state and the `num_replicated` other arguments (the key, ...) replicated."""
    n = mesh.devices.size
    if batch_size % n:
        raise ValueError(f"train.batch_size {batch_size} is not divisible by the {n} devices")
    rep, shard = replicated(mesh), batch_sharded(mesh)
    return jax.jit(train_step, in_shardings=(rep, shard) + (rep,) * num_replicated, out_shardings=(rep, rep),
                   donate_argnums=0)


def put_state(state, mesh: Mesh):
    """The state replicated over the mesh; its arrays must be the same in every process (they are:
    the same seed, or the same checkpoint). Host copies first: a committed local array cannot be
    put on another process's devices."""
    return jax.device_put(jax.device_get(state), replicated(mesh))


def put_key(key, mesh: Mesh):
    """A PRNG key replicated over the mesh (as its raw data: typed keys do not cross processes)."""
    data = jax.device_put(np.asarray(jax.random.key_data(key)), replicated(mesh))
    return jax.random.wrap_key_data(data, impl=jax.random.key_impl(key))


def global_batch(batch, mesh: Mesh):
    """The global batch as an array sharded over the mesh, from this process's copy of the whole
    batch: each local device takes its own rows (module doc)."""
    sharding = batch_sharded(mesh)
    return jax.tree.map(lambda x: jax.make_array_from_callback(x.shape, sharding, lambda idx: x[idx]), batch)


def local_copy(tree):
    """This process's copy of replicated arrays, on its first local device: for work one process
    does alone (previews), which must not wait for the others."""
    return jax.tree.map(lambda x: x.addressable_data(0) if isinstance(x, jax.Array) else x, tree)
