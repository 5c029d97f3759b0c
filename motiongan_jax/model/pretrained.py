"""Inference exports: a trained G in one small file, and the model shipped with the package.

An export is an .npz holding what generation and analysis need and nothing else:
- `g/<path>`: G's parameters (the moving average by default, see model.state.inference_state),
  Latent Transform included, float32, one entry per leaf of `state.g_params`;
- `meta`: the checkpoint's meta as JSON (config, style names, skeleton layout, fps), without the
  machine-specific data directory;
- `provenance`: JSON with the config hash, seed, steps, which parameters (ema/raw), the source
  commit of the code that exported it (and whether its tracked files were modified), the jax /
  flax / numpy versions;
- `params_sha256`: SHA-256 of the parameters alone (the same weights give the same value
  whatever the provenance says: the test of a bit-for-bit reproduction);
- `sha256`: SHA-256 of every other entry, checked on every load, so a truncated or edited file
  is refused rather than generating from damaged weights.
Digests are taken over (name, dtype, shape, bytes) of each entry in name order, so they do not
depend on how the zip was written; the zip itself is written deterministically (fixed entry
order and timestamps) so the same export is also the same bytes.

`load_export(path)` returns (state, meta, cfg, layout) like checkpoint.load_run: a TrainState
with G's parameters and graph definition (D, optimiser and moving-average fields None), which
generate.py, analysis.py and the demo use unchanged. `load_model(workdir=None, ...)` is what
the command-line tools call: a run's checkpoint when a workdir is given, an export file with
`model=`, else SHIPPED_MODEL.
"""

from __future__ import annotations

import dataclasses
import hashlib
import io
import json
import subprocess
import zipfile
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from motiongan_jax import atomic
from motiongan_jax.model import checkpoint

SHIPPED_MODEL = Path(__file__).resolve().parent.parent / "weights" / "small.npz"
FORMAT = "motiongan_jax inference export"
VERSION = 1
_PARAM_PREFIX = "g/"
_ZIP_TIME = (1980, 1, 1, 0, 0, 0)  # zip's earliest date: the same file bytes on every export
_KEEP_FIELDS = ("g_params", "step")  # the state fields an export restores; the others are None


class ExportError(checkpoint.CheckpointError):
    """A missing, damaged or incompatible export file; the message says which and why."""


# ---------------------------------------------------------------------------------------------
# Writing
# ---------------------------------------------------------------------------------------------


def _leaf_name(path) -> str:
    return _PARAM_PREFIX + jax.tree_util.keystr(path, simple=True, separator="/")


def _flat_params(g_params) -> dict[str, np.ndarray]:
    leaves = jax.tree_util.tree_flatten_with_path(g_params)[0]
    out = {_leaf_name(p): np.asarray(v) for p, v in leaves}
    if len(out) != len(leaves):
        raise ExportError("G's parameter names collide when flattened; cannot export")
    return out


def _c_order(a) -> np.ndarray:
    """C-ordered, keeping 0-d arrays 0-d (np.ascontiguousarray would make them 1-d)."""
    return np.require(a, requirements="C")


def _digest(arrays: dict[str, np.ndarray], names) -> str:
    h = hashlib.sha256()
    for name in sorted(names):
        a = _c_order(arrays[name])
        for part in (name, a.dtype.str, repr(a.shape)):
            h.update(part.encode() + b"\0")
        h.update(a.tobytes())
    return h.hexdigest()


def _git(*args) -> str | None:
    try:
        out = subprocess.run(["git", *args], cwd=Path(__file__).resolve().parent, capture_output=True,
                             text=True, timeout=10, check=True)
    except (OSError, subprocess.SubprocessError):
        return None
    return out.stdout.strip()


def source_commit() -> tuple[str | None, bool | None]:
    """(HEAD commit of the checkout this package runs from, whether tracked files differ from it);
    (None, None) outside a git checkout."""
    commit = _git("rev-parse", "HEAD")
    if not commit:
        return None, None
    status = _git("status", "--porcelain", "--untracked-files=no")
    return commit, (None if status is None else bool(status))


def export_state(out, state, meta: dict, *, params: str) -> dict:
    """Writes the export of an inference state (G's parameters already chosen: `params` says
    which, "ema" or "raw") atomically to `out`; returns its provenance with both digests."""
    import flax

    from motiongan_jax.config import config_hash, from_dict

    cfg = from_dict(meta["config"])
    arrays = _flat_params(state.g_params)
    commit, dirty = source_commit()
    provenance = {  # the config's name and hash as the run saved it (its config_hash)
        "format": FORMAT, "version": VERSION, "config_name": meta["config"].get("name", cfg.name),
        "config_hash": config_hash(meta["config"]),
        "seed": int(cfg.train.seed), "steps": int(state.step), "params": params,
        "source_commit": commit, "source_modified": dirty,
        "jax": jax.__version__, "flax": flax.__version__, "numpy": np.__version__,
    }
    return _write_export(out, arrays, {**meta, "data_dir": None}, provenance)


def _write_export(out, params: dict[str, np.ndarray], meta: dict, provenance: dict) -> dict:
    """Writes G's flat parameters with meta and provenance, both digests taken, atomically and
    deterministically; returns the provenance with the digests."""
    arrays = dict(params)
    arrays["meta"] = np.array(json.dumps(meta, sort_keys=True))
    arrays["provenance"] = np.array(json.dumps(provenance, sort_keys=True))
    arrays["params_sha256"] = np.array(_digest(arrays, [n for n in arrays if n.startswith(_PARAM_PREFIX)]))
    arrays["sha256"] = np.array(_digest(arrays, list(arrays)))
    out = Path(out)
    if not out.parent.is_dir():
        raise ExportError(f"cannot write {out}: directory {out.parent} does not exist")
    with atomic.atomic_path(out) as tmp:
        with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as zf:
            for name in sorted(arrays):
                info = zipfile.ZipInfo(name + ".npy", date_time=_ZIP_TIME)
                info.compress_type = zipfile.ZIP_DEFLATED
                info.external_attr = 0o644 << 16
                buf = io.BytesIO()
                np.lib.format.write_array(buf, _c_order(arrays[name]), allow_pickle=False)
                zf.writestr(info, buf.getvalue())
    return {**provenance, "params_sha256": str(arrays["params_sha256"]), "sha256": str(arrays["sha256"])}


def upgrade_export(path, out) -> dict:
    """An export written by an earlier version, rewritten with its meta's config in the current
    schema (config.upgrade; the weights untouched, so `params_sha256` stays); the provenance keeps
    the old config hash and file digest under "upgraded_from". Returns the new provenance."""
    from motiongan_jax.config import ConfigError, config_hash, from_dict, to_dict

    old = read_export(path)
    try:
        config = to_dict(from_dict(old.meta["config"]))
    except (ConfigError, KeyError, TypeError) as err:
        raise ExportError(f"model file {old.path}: its config cannot be upgraded ({err})") from None
    provenance = {**old.provenance, "config_hash": config_hash(config),
                  "upgraded_from": {"config_hash": old.provenance["config_hash"], "sha256": old.sha256}}
    info = _write_export(out, old.params, {**old.meta, "config": config}, provenance)
    if info["params_sha256"] != old.params_sha256:  # the same arrays digest the same: a guard
        raise ExportError(f"upgrading {old.path} changed its weights")
    return info


def export_run(workdir, out, *, step: int | None = None, params: str = "ema") -> dict:
    """The export of a training run's checkpoint (`step`, or the run's model:
    checkpoint.resolve_step); its provenance.
    params "ema" exports G's moving average when the run keeps one (else the trained
    parameters, and the provenance says "raw"), "raw" the trained parameters."""
    state, meta, _, _ = checkpoint.load_run(workdir, step, params)
    with_ema = meta["config"]["train"].get("g_ema_decay", 0.0) > 0
    return export_state(out, state, meta, params="ema" if params == "ema" and with_ema else "raw")


# ---------------------------------------------------------------------------------------------
# Reading
# ---------------------------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class Export:
    path: Path
    meta: dict
    provenance: dict
    params: dict[str, np.ndarray]  # "g/<path>" -> array
    params_sha256: str
    sha256: str

    def describe(self) -> str:
        p = self.provenance
        commit = (p.get("source_commit") or "unknown")[:12] + (" (modified)" if p.get("source_modified") else "")
        return (f"{self.path.name}: config {p['config_name']} ({p['config_hash']}), seed {p['seed']}, "
                f"{p['steps']} steps, {p['params']} parameters, commit {commit}, sha256 {self.sha256[:16]}")


def read_export(path) -> Export:
    """An export file, its checksum verified; ExportError when missing, damaged or modified."""
    path = Path(path)
    if not path.is_file():
        raise ExportError(f"model file {path} not found")
    if not zipfile.is_zipfile(path):  # numpy would take any other file for a pickle and say so
        raise ExportError(f"model file {path} cannot be read as an export: not an .npz (zip) file")
    try:
        with np.load(path, allow_pickle=False) as z:
            arrays = {name: z[name] for name in z.files}
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as err:
        raise ExportError(f"model file {path} cannot be read as an export: {err}") from None
    missing = [k for k in ("meta", "provenance", "params_sha256", "sha256") if k not in arrays]
    if missing:
        raise ExportError(f"model file {path} is not a motiongan_jax export (no {', '.join(missing)})")
    stored = str(arrays.pop("sha256"))
    actual = _digest(arrays, list(arrays))
    if actual != stored:
        raise ExportError(f"model file {path} fails its checksum (stored sha256 {stored[:16]}..., "
                          f"contents {actual[:16]}...): the file is damaged or was modified")
    try:
        meta, provenance = json.loads(str(arrays["meta"])), json.loads(str(arrays["provenance"]))
    except json.JSONDecodeError as err:
        raise ExportError(f"model file {path}: unreadable meta ({err})") from None
    if provenance.get("format") != FORMAT or provenance.get("version") != VERSION:
        raise ExportError(f"model file {path}: format {provenance.get('format')!r} version "
                          f"{provenance.get('version')!r}, this code reads {FORMAT!r} version {VERSION}")
    params = {k: v for k, v in arrays.items() if k.startswith(_PARAM_PREFIX)}
    return Export(path, meta, provenance, params, str(arrays["params_sha256"]), stored)


def state_from_export(export: Export):
    """(state, meta, cfg, layout) of an export; ExportError when its parameters do not fit the
    model its config describes (e.g. an export from other code)."""
    try:
        cfg, layout, like = checkpoint.abstract_model(export.meta)
    except (KeyError, TypeError, ValueError) as err:
        raise ExportError(f"model file {export.path}: its meta does not describe a model this code "
                          f"builds ({type(err).__name__}: {err})") from None
    leaves, treedef = jax.tree_util.tree_flatten_with_path(like.g_params)
    names = [_leaf_name(p) for p, _ in leaves]
    extra, absent = sorted(set(export.params) - set(names)), sorted(set(names) - set(export.params))
    if extra or absent:
        raise ExportError(f"model file {export.path} does not fit this model: "
                          f"{len(absent)} parameters missing (e.g. {absent[:2]}), "
                          f"{len(extra)} unexpected (e.g. {extra[:2]})")
    values = []
    for name, (_, spec) in zip(names, leaves):
        a = export.params[name]
        if a.shape != spec.shape or a.dtype != spec.dtype:
            raise ExportError(f"model file {export.path}: {name} is {a.dtype}{list(a.shape)}, this "
                              f"model needs {spec.dtype}{list(spec.shape)}")
        values.append(jnp.asarray(a))
    kept = {"g_params": jax.tree_util.tree_unflatten(treedef, values),
            "step": jnp.asarray(export.provenance["steps"], jnp.int32)}
    cleared = {f.name: None for f in dataclasses.fields(like)
               if f.metadata.get("pytree_node", True) and f.name not in _KEEP_FIELDS}
    return like.replace(**kept, **cleared), export.meta, cfg, layout


def load_export(path):
    """(state, meta, cfg, layout) from an export file (checksum checked)."""
    return state_from_export(read_export(path))


def load_model(workdir=None, step: int | None = None, params: str = "ema", model=None):
    """(state, meta, cfg, layout): a run's checkpoint when `workdir` is given, else the export
    file `model`, else the shipped model. `step` and params "raw" need a run's checkpoints (an
    export holds one set of parameters)."""
    if workdir is not None:
        if model is not None:
            raise ExportError("give a run's workdir or a model file, not both")
        return checkpoint.load_run(workdir, step, params)
    export = read_export(SHIPPED_MODEL if model is None else model)
    if step is not None:
        raise ExportError(f"{export.path.name} holds one step ({export.provenance['steps']}); "
                          "--step needs a run's --workdir")
    if params != export.provenance["params"] and params == "raw":
        raise ExportError(f"{export.path.name} holds G's {export.provenance['params']} parameters; "
                          "--params raw needs a run's --workdir")
    return state_from_export(export)


def model_meta(workdir=None, step: int | None = None, model=None) -> dict:
    """The meta (style names, skeleton, config) of what load_model would load, without the weights
    of a run's checkpoint."""
    if workdir is not None:
        return checkpoint.read_meta(checkpoint.run_manager(workdir), step)[1]
    return read_export(SHIPPED_MODEL if model is None else model).meta

