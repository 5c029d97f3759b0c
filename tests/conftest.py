"""Shared pytest fixtures and helpers (docs/TESTING.md).

The expensive artifacts (the tiny config trained for its 4 steps, a checkpoint with seeded random
parameters) are built once per test run, not once per xdist worker: `_build_once` makes each under
a file lock in a folder every worker sees, in a temporary directory renamed into place when
complete, so no test ever reads a half-built one. Tests only read them (checked at the end).
"""

from __future__ import annotations

import contextlib
import fcntl
import importlib
import io
import os
import shutil
import subprocess
import sys
import tempfile
import types
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]

# Compile time dominates on CPU. These options change how fast a program runs and how XLA
# generates its code, not what the tests compare: both sides of every bit-for-bit comparison are
# compiled alike. The older loop emitters (fusion emitters off) compile the tiny train step in a
# third of the CPU time (docs/TESTING.md).
FAST = {"xla_backend_optimization_level": 0, "xla_llvm_disable_expensive_passes": True,
        "xla_cpu_use_fusion_emitters": False}


def _xla_knows(option: str) -> bool:
    """Whether this jaxlib's XLA has the compile option `option`, asked in a child process: an
    unknown flag in XLA_FLAGS aborts every process that starts XLA."""
    code = f"import jax; jax.jit(lambda: 0).lower().compile(compiler_options={{{option!r}: False}})"
    env = {**os.environ, "JAX_PLATFORMS": "cpu"}
    return subprocess.run([sys.executable, "-c", code], env=env, capture_output=True).returncode == 0


if "MOTIONGAN_TEST_FAST" not in os.environ:  # pytest's own process (xdist's workers inherit the result)
    if not _xla_knows("xla_cpu_use_fusion_emitters"):  # an XLA before or after that option
        del FAST["xla_cpu_use_fusion_emitters"]
    os.environ["MOTIONGAN_TEST_FAST"] = ",".join(FAST)
    # ... for every program of the run too, including those of the tools the tests start (they
    # inherit the environment; XLA reads it when its CPU client starts, after this). The caller's
    # flags come first.
    os.environ["XLA_FLAGS"] = " ".join(
        [os.environ.get("XLA_FLAGS", "")] + [f"--{k}={str(v).lower()}" for k, v in FAST.items()]).strip()
FAST = {k: v for k, v in FAST.items() if k in os.environ["MOTIONGAN_TEST_FAST"].split(",")}
# ... except for the style search's program (analysis.search._search, Adam steps through G's
# backward pass in a scan): level 0 runs it about 19x slower than level 1 (28 s against 1.5 s for 3
# steps on the shipped model) while level 1 compiles it in 21 s against 8 s (docs/TESTING.md), so the
# tests compile that one program at level 1 (`_search_at_level_1`)
SEARCH_OPTIONS = {**FAST, "xla_backend_optimization_level": 1}


def compiled(fn, *args):
    """`fn` jitted and compiled for `args` with the FAST options."""
    import jax

    return jax.jit(fn).lower(*args).compile(compiler_options=FAST)


def compiled_call(module, *args, **kwargs):
    """module(*args, **kwargs) for an nnx module, as one program compiled with FAST (run op by
    op, G and D compile each of their hundreds of ops on its own)."""
    from flax import nnx

    graphdef, state = nnx.split(module)
    return compiled(lambda state, *a: nnx.merge(graphdef, state)(*a, **kwargs), state, *args)(state, *args)


# The files whose tests take longest in all (docs/TESTING.md, Durations), longest first: with
# `--dist loadfile` (pyproject.toml) xdist hands whole files to the workers in collection order,
# and longest-first keeps the two workers' shares even.
SLOW_FILES = ("test_train.py", "test_multiprocess.py", "test_default_xla.py", "test_step.py",
              "test_fast_equals_reference.py", "test_evaluation.py", "test_analysis.py", "test_notebook.py",
              "test_generate.py", "test_hostile.py", "test_nn.py", "test_parallel.py", "test_curves.py",
              "test_pretrained.py", "test_losses.py", "test_data.py")


def pytest_collection_modifyitems(config, items):
    rank = {name: i for i, name in enumerate(SLOW_FILES)}
    items.sort(key=lambda item: rank.get(item.path.name, len(SLOW_FILES)))  # stable: each file's own order


def load_cli(name: str):
    """motiongan_jax.cli.NAME, the tool behind bin/NAME.py (its `main(argv)` returns the exit status)."""
    return importlib.import_module(f"motiongan_jax.cli.{name}")


def run_cli(name: str, argv) -> tuple[int, str, str]:
    """(exit status, stdout, stderr) of the tool NAME's main(argv), in this process; a SystemExit
    (argparse's usage errors) counts as its exit status."""
    main = load_cli(name).main
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main([str(a) for a in argv])
        except SystemExit as e:
            code = e.code if isinstance(e.code, int) else (0 if e.code is None else 1)
    return code, out.getvalue(), err.getvalue()


STATE_FIELDS = ("g_params", "d_params", "d_sn_state", "opt_g_state", "opt_d_state", "g_ema_params")


def assert_bit_identical(a, b, fields=STATE_FIELDS):
    """Every leaf of the named TrainState fields of `a` and `b` is equal, bit for bit."""
    import jax
    import numpy as np

    la = jax.tree.leaves(tuple(getattr(a, f) for f in fields))
    lb = jax.tree.leaves(tuple(getattr(b, f) for f in fields))
    assert len(la) == len(lb)
    for x, y in zip(la, lb):
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))


def random_run(cfg, wd, step: int = 4, seed: int = 0, data_dir: str = "<test>"):
    """A checkpoint of `cfg` with seeded random parameters, saved as training saves one
    (jax.eval_shape of init_state gives the structure without compiling the initialisers)."""
    import jax
    import numpy as np

    from motiongan_jax.data import synthetic
    from motiongan_jax.model import checkpoint
    from motiongan_jax.model import state as model_state
    from motiongan_jax.motion import representation
    from motiongan_jax.train import loop as train_lib

    layout = representation.layout_from_skeleton(synthetic.cmu_skeleton(), synthetic.UNITS_TO_M)
    styles = tuple(sorted(synthetic.STYLES))
    dataset = types.SimpleNamespace(style_names=styles, layout=layout, fps=60.0, data_dir=data_dir)
    like = jax.eval_shape(lambda: model_state.init_state(cfg, layout, len(styles), jax.random.key(0)))
    rng = np.random.default_rng(seed)
    state = jax.tree.map(lambda s: rng.normal(0, 0.3, s.shape).astype(s.dtype)
                         if np.issubdtype(s.dtype, np.floating) else np.zeros(s.shape, s.dtype), like)
    checkpoint.save(checkpoint.manager(Path(wd) / "checkpoints"), step, state, train_lib.run_meta(cfg, dataset))
    return Path(wd)


# ---------------------------------------------------------------------------------------------
# artifacts shared by every worker


def _shared_root(tmp_path_factory) -> Path:
    """This run's base temporary folder: under xdist the parent of every worker's own."""
    root = tmp_path_factory.getbasetemp()
    return root.parent if root.name.startswith("popen-gw") else root


def _listing(path: Path) -> list:
    return sorted((str(p.relative_to(path)), p.stat().st_size, p.stat().st_mtime_ns) for p in path.rglob("*"))


def _build_once(tmp_path_factory, name: str, build) -> Path:
    """ROOT/NAME, made by `build(tmp_dir)` in the first worker to get here (the others wait on the
    lock) and renamed into place only once complete; a failed build leaves nothing."""
    root = _shared_root(tmp_path_factory)
    final = root / name
    with open(root / f".{name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not final.is_dir():
            tmp = Path(tempfile.mkdtemp(dir=root, prefix=f".{name}."))
            try:
                build(tmp)
                os.rename(tmp, final)
            finally:
                shutil.rmtree(tmp, ignore_errors=True)
    return final


@contextlib.contextmanager
def _read_only(path: Path):
    """Yields `path` and fails the run at its end if any test changed a file there."""
    before = _listing(path)
    yield path
    assert _listing(path) == before, f"a test wrote into the shared {path.name}: copy it first"


@pytest.fixture(scope="session")
def tiny_cfg():
    from motiongan_jax.config import load_config

    return load_config(REPO / "configs" / "tiny.py")


@pytest.fixture(scope="session")
def trained_tiny(tiny_cfg, tmp_path_factory):
    """The tiny config trained for its 4 steps without interruption (seed 0): the reference of the
    training tests and the model of the analysis tests. Read only."""
    from motiongan_jax.train import loop as train_lib

    path = _build_once(tmp_path_factory, "trained_tiny",
                       lambda wd: train_lib.train(tiny_cfg, wd, progress=False, log=lambda s: None))
    with _read_only(path):
        yield path


@pytest.fixture(scope="session")
def random_tiny(tiny_cfg, tmp_path_factory):
    """The tiny config's G and D with seeded random parameters, as a checkpoint at step 4 of a run
    on the embedded dataset: checkpoints/ alone (what generation reads). Read only."""
    from motiongan_jax.data import clip_cache
    def build(wd):
        random_run(tiny_cfg, wd, data_dir=str(clip_cache.resolve_data_dir(tiny_cfg.data)))

    path = _build_once(tmp_path_factory, "random_tiny", build)
    with _read_only(path):
        yield path


# ---------------------------------------------------------------------------------------------
# the environment of every test


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """The shared motion data folder (../shared/data beside the checkout, or $MOTIONGAN_SHARED_DATA)."""
    default = REPO.parent / "shared" / "data"
    path = Path(os.environ.get("MOTIONGAN_SHARED_DATA", default))
    if not path.is_dir():
        pytest.skip(f"shared data not found at {path}: set MOTIONGAN_SHARED_DATA")
    return path


@pytest.fixture(scope="session", autouse=True)
def _private_cache(tmp_path_factory):
    """Tests never read or write the user's cache (the embedded dataset, preprocessed clips). The
    workers share one (its writes are atomic and race-safe), so the embedded dataset is generated
    once and every run made on it names the same data folder."""
    old = os.environ.get("MOTIONGAN_CACHE")
    path = _shared_root(tmp_path_factory) / "motiongan_cache"
    path.mkdir(exist_ok=True)
    os.environ["MOTIONGAN_CACHE"] = str(path)
    yield
    if old is None:
        os.environ.pop("MOTIONGAN_CACHE", None)
    else:
        os.environ["MOTIONGAN_CACHE"] = old


@pytest.fixture(scope="session", autouse=True)
def _compilation_cache(tmp_path_factory):
    """One persistent XLA compilation cache for the whole run, shared by the xdist workers and the
    command-line tools the tests start: a program that another process already compiled (the tiny
    train step in every `bin/train.py` restart, say) is loaded instead of compiled again. Keys
    cover the program, the options and the versions, so a hit computes exactly what a compile would."""
    import jax

    path = _shared_root(tmp_path_factory) / "jax_compilation_cache"
    path.mkdir(exist_ok=True)
    # every program, not only those over JAX's 1 s: each tool a test starts compiles dozens of
    # small ones (the init, the batch sampler, the codes) that an earlier process already has
    settings = {"JAX_COMPILATION_CACHE_DIR": ("jax_compilation_cache_dir", str(path)),
                "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS": ("jax_persistent_cache_min_compile_time_secs", 0.0)}
    old = {env: os.environ.get(env) for env in settings}
    old_config = {name: getattr(jax.config, name) for name, _ in settings.values()}
    for env, (name, value) in settings.items():
        os.environ[env] = str(value)
        jax.config.update(name, value)
    yield
    for env, (name, _) in settings.items():
        jax.config.update(name, old_config[name])
        if old[env] is None:
            os.environ.pop(env, None)
        else:
            os.environ[env] = old[env]


@pytest.fixture(scope="session", autouse=True)
def _search_at_level_1():
    """The style search's program compiled with SEARCH_OPTIONS in this process (the same function;
    only XLA's code generation differs)."""
    from motiongan_jax.analysis import search

    original = search._search
    search._search = search_at_level_1(original)
    yield
    search._search = original


def search_at_level_1(search_fn):
    """analysis.search._search (`search_fn`, a jitted function) jitted again with SEARCH_OPTIONS."""
    import jax

    return jax.jit(search_fn.__wrapped__, static_argnames=("loss", "keep", "steps"), compiler_options=SEARCH_OPTIONS)


# `python -c SERVE_DEMO ARGS...` is `python -m motiongan_jax.demo ARGS...` with the style search's
# program at level 1, as in the tests' own processes
SERVE_DEMO = f"""
import runpy, sys
sys.path.insert(0, {str(Path(__file__).parent)!r})
import conftest
from motiongan_jax.analysis import search
search._search = conftest.search_at_level_1(search._search)
runpy.run_module("motiongan_jax.demo", run_name="__main__", alter_sys=True)
"""


@pytest.fixture(scope="session")
def repo() -> Path:
    return REPO



# ---------------------------------------------------------------------------------------------
# a walk without a model


# joint names of the toy walk on each skeleton it can walk (the root's rotation turns the body)
_TOY_NAMES = {
    "cmu": {"root": "Hips", "turn": "Hips", "spine": "Spine", "head": "Head",
            **{f"{s}_{k}": f"{side}{n}" for s, side in (("l", "Left"), ("r", "Right"))
               for k, n in (("hip", "UpLeg"), ("knee", "Leg"), ("ankle", "Foot"), ("toe", "ToeBase"),
                            ("arm", "Arm"), ("forearm", "ForeArm"))}},
    "bandai": {"root": "joint_Root", "turn": "joint_Root", "spine": "Spine", "head": "Head",
               **{f"{s}_{k}": f"{n}_{s.upper()}" for s in ("l", "r")
                  for k, n in (("hip", "UpperLeg"), ("knee", "LowerLeg"), ("ankle", "Foot"), ("toe", "Toes"),
                               ("arm", "UpperArm"), ("forearm", "LowerArm"))}},
}


def toy_walk(frames: int = 45, fps: float = 15.0, skeleton: str = "cmu", knee_min_deg: float = 0.0):
    """(positions (F, J, 3) metres on the skeleton's layout, layout, the bvh.Motion they are the
    forward kinematics of): a cheap stand-in for a generated walk, on the project's own CMU-named
    skeleton (the embedded dataset's, its zero-length joints at rest) or, with skeleton="bandai",
    the built-in Bandai-named rig. Hips, knees and arms swing at 0.9 Hz, the body turns left, and
    the root moves so that the lower toe stays where it is (feet planted), the lowest joint on the
    floor. The knees straighten fully in stance unless `knee_min_deg` keeps them bent that much, as
    people's do (six of Bandai's clips: 3-30 degrees at their straightest; the shipped model's walk 11)."""
    import numpy as np

    from motiongan_jax.data import synthetic
    from motiongan_jax.motion import bvh, kinematics, representation, rigs

    if skeleton == "cmu":
        sk, units = synthetic.cmu_skeleton(), synthetic.UNITS_TO_M
    else:
        sk, units = rigs.builtin_skeleton(skeleton)
    name = _TOY_NAMES[skeleton]
    t = np.arange(frames) / fps
    ph = 2 * np.pi * 0.9 * t
    values = np.zeros((frames, sk.num_channels))
    sl = dict(zip(sk.names, sk.channel_slices()))

    def put(role, axis, deg):  # channels Zrotation Yrotation Xrotation (root: after 3 positions)
        s = sl[name[role]]
        values[:, s.start + (3 if name[role] == name["root"] else 0) + "ZYX".index(axis)] = deg

    put("turn", "Y", np.degrees(0.35 * t))  # turning left
    for side, sign in (("l", 1.0), ("r", -1.0)):
        put(f"{side}_hip", "X", -25 * sign * np.sin(ph))
        put(f"{side}_knee", "X", knee_min_deg + (50 - knee_min_deg) * np.maximum(0, sign * np.cos(ph)))
        put(f"{side}_ankle", "X", -10 * sign * np.sin(ph))
        put(f"{side}_arm", "X", 20 * sign * np.sin(ph))
        put(f"{side}_arm", "Z", -sign * 70.0)  # arms down from the T-pose
        put(f"{side}_forearm", "Y", sign * 20 * (1 + np.sin(ph)))
    put("spine", "Y", 5 * np.sin(ph))
    put("head", "X", 8.0)
    rel = kinematics.world_positions(bvh.Motion(sk, 1.0 / fps, values))  # the root at the origin
    toes = rel[:, [sk.names.index(name["l_toe"]), sk.names.index(name["r_toe"])]]
    stance = np.argmin(toes[..., 1], axis=1)
    step = toes[1:, :, [0, 2]] - toes[:-1, :, [0, 2]]
    moved = -step[np.arange(frames - 1), stance[1:]]
    root = values[:, sl[name["root"]].start:sl[name["root"]].start + 3]
    root[1:, [0, 2]] = np.cumsum(moved, axis=0)
    root[:, 1] = -rel[..., 1].min(axis=1)
    motion = bvh.Motion(sk, 1.0 / fps, values)
    layout = representation.layout_from_skeleton(sk, units)
    world = kinematics.world_positions(motion) * units
    return world[:, list(layout.source_index)], layout, motion
