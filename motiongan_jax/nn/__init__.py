"""Networks (Flax NNX, NHWC = (B, T, W, C)): the paper's G with its Latent Transform and the
small configs' walker around it; the paper's D and its projection variant."""

from __future__ import annotations

import functools
from typing import Callable

import jax
from flax import nnx

from motiongan_jax.nn.discriminator import Discriminator, ProjectionDiscriminator
from motiongan_jax.nn.generator import Generator
from motiongan_jax.nn.latent import LatentTransform
from motiongan_jax.nn.layers import SpectralNormState
from motiongan_jax.nn.walker import WalkerGenerator


def count_params(module: nnx.Module) -> int:
    """Trainable parameters (nnx.Param); spectral-norm u/v are state, not counted."""
    return sum(int(x.size) for x in jax.tree_util.tree_leaves(nnx.state(module, nnx.Param)))


# Initialisation is ~100 separate threefry draws, and XLA's CPU backend spends long optimising
# them (each draw is unrolled code). The init runs once, so it is compiled with the backend
# optimiser off: much faster to compile, same random bits (threefry is integer code; the float
# maps to normal/uniform may differ from an eager init in the last place).
_FAST_COMPILE = {"xla_backend_optimization_level": 0, "xla_llvm_disable_expensive_passes": True}


@functools.lru_cache(maxsize=16)
def _compiled_init(build: Callable, build_args: tuple, filters: tuple, key_aval, build_kwargs: tuple = ()):
    """(graphdef, the compiled function key -> states): the module is built once, under jit's
    trace, which also gives its graphdef (a second build under eval_shape cost as much again)."""
    graphdefs = []

    def arrays(key):
        graphdef, *states = nnx.split(build(*build_args, key, **dict(build_kwargs)), *filters)
        graphdefs.append(graphdef)
        return tuple(states)

    lowered = jax.jit(arrays).lower(key_aval)
    try:
        compiled = lowered.compile(compiler_options=_FAST_COMPILE)
    except Exception:  # a backend without these debug options: compile normally
        compiled = lowered.compile()
    return graphdefs[0], compiled


def init_split(build: Callable[..., nnx.Module], build_args: tuple, key: jax.Array, *filters,
               build_kwargs: tuple = ()):
    """`nnx.split(build(*build_args, key, **dict(build_kwargs)), *filters)`, the arrays made by one
    cached jit that is compiled fast. `build`, `build_args` and `build_kwargs` (pairs) must be
    hashable (a module-level function and e.g. ints, strings and frozen configs), so that
    repeated inits reuse the compiled function.
    Returns (graphdef, state for filter 0, state for filter 1, ...). Under a trace (e.g.
    jax.eval_shape of an init) it simply traces `build`.
    """
    if isinstance(key, jax.core.Tracer):  # inside jit / eval_shape: just trace it
        return nnx.split(build(*build_args, key, **dict(build_kwargs)), *filters)
    key_aval = jax.ShapeDtypeStruct(key.shape, key.dtype)
    graphdef, compiled = _compiled_init(build, tuple(build_args), tuple(filters), key_aval, tuple(build_kwargs))
    return (graphdef, *compiled(key))


__all__ = ["Discriminator", "Generator", "LatentTransform", "ProjectionDiscriminator", "SpectralNormState",
           "WalkerGenerator", "count_params", "init_split"]
