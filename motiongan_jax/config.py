"""Configs as data: one frozen dataclass tree, and the named presets (`paper`, `bandai`,
`small`, `bandai_small`, `tiny`; configs/*.py are their entry points for the command line).

Every field can be overridden from the command line with `--set section.field=value`
(see `override`). `validate` rejects bad values before anything is compiled. A string option's
allowed values are its `Literal` type, the one list that `validate` and the code read.
Configs saved by older versions load through `upgrade`, the one map from old schemas to this one.
"""

from __future__ import annotations

import ast
import dataclasses
import hashlib
import importlib.util
import json
from pathlib import Path
from typing import Any, Literal, get_args, get_origin, get_type_hints

# The paper's 28 classes, in the order that fixes label indices 0..27 (docs/DESIGN.md §2.1).
PAPER_STYLES = (
    "Cat", "Chicken", "Dinosaur", "Drunk", "GanglyTeen", "GracefulLady", "Normal", "OldMan",
    "SexyLady", "StrongMan", "Childish", "Clumsy", "Cool", "Depressed", "Elated", "Elderlyman",
    "Happy", "Joy", "Lavish", "Marching", "Painfulleftknee", "Relaxed", "Rushed", "Sad", "Scared",
    "Sexy", "Shy", "Sneaky",
)

LabelRule = Literal["paper", "bandai", "bandai_session", "cmu", "synthetic"]
LatentInit = Literal["paper", "torch_default"]
GFrame = Literal["world", "curve"]
GanLoss = Literal["bce_prob", "bce_logit"]
ConvImpl = Literal["fast", "xla"]
ComputeDtype = Literal["float32", "bfloat16"]
RecZ = Literal["zero", "sampled"]


def choices(literal) -> tuple[str, ...]:
    """The allowed values of a Literal option type, e.g. choices(GFrame) == ("world", "curve")."""
    return get_args(literal)


class ConfigError(ValueError):
    """A config value is invalid; the message names the field."""


@dataclasses.dataclass(frozen=True)
class DataConfig:
    # BVH directory; None trains on the embedded default (procedural) dataset.
    data_dir: str | None = None
    # How style labels are read from file names: paper `<Style>_*.bvh`, bandai
    # `dataset-N_<content>_<style>_<trial>.bvh`, cmu `<subject>_<trial>.bvh` via the shipped table,
    # synthetic: the embedded dataset's own names (same shape as paper).
    label_rule: LabelRule = "synthetic"
    # Style names in label-index order; empty means "every style found, sorted".
    styles: tuple[str, ...] = ()
    # Metres per file unit; None infers it from the label rule (representation.UNITS_TO_M).
    units_to_m: float | None = None
    # Leading frames dropped from every clip (CMU frame 0 is a T-pose).
    start_offset: int = 1
    # Frames between spline control points of the input curve (paper: 256 at 120 fps).
    control_point_interval: int = 256
    # Window length in source frames and the subsampling step; T = frame_nums // frame_step.
    frame_nums: int = 1024
    frame_step: int = 8
    # Frames between consecutive window starts.
    window_stride: int = 3
    # FPS augmentation: playback-speed factors drawn uniformly (paper: 0.5, 1, 1.5); (1.0,) is none.
    fps_factors: tuple[float, ...] = (0.5, 1.0, 1.5)
    # Random rotation about the vertical axis.
    rotate: bool = True
    # Curve noise as a fraction of the step (timing) and of the point spacing (space); paper 0.02.
    curve_noise: float = 0.02
    # Validation split: trials whose number % val_modulus == val_remainder are held out;
    # val_modulus 0 holds nothing out (the paper trained on every CMU trial).
    val_modulus: int = 4
    val_remainder: int = 0
    # Seed of the embedded default dataset.
    synthetic_seed: int = 0

    @property
    def window_T(self) -> int:
        return self.frame_nums // self.frame_step


@dataclasses.dataclass(frozen=True)
class WalkerConfig:
    """The small presets' G: the paper's G with the walker's parts around it (nn/walker.py), each
    measured in docs/RESULTS.md §5-§10. Every part is on in the presets; a part off is an ablation."""
    # G adds the skeleton's rest pose to its pose head and the curve's velocity to its root head,
    # so it starts from a skeleton of the right size on the curve (the paper's G starts near zero).
    output_prior: bool = True
    # G's frame: "curve" (G sees the curve from the walker's heading, so the body faces its path
    # for every rotation; RESULTS §5) or "world" (the paper's).
    frame: GFrame = "curve"
    # G's bones take the skeleton's lengths exactly, keeping the directions G outputs (RESULTS §9).
    exact_bones: bool = True
    # G keeps a clock in walked distance at a learned per-style stride and sees its phase (RESULTS §10).
    gait_phase: bool = True
    # G's stride follows the walking speed as the data's does (log stride linear in log speed at
    # the slope fitted within styles; off: one stride per style whatever the speed; RESULTS §24).
    # Needs gait_phase.
    stride_speed: bool = True
    # G's root head gives the root's height, not its vertical velocity: no drift off the floor.
    root_height: bool = True


@dataclasses.dataclass(frozen=True)
class ModelConfig:
    """The networks. Every option below departs from the paper only when on (True, or its
    non-paper value); the small presets turn them on (docs/RESULTS.md §5-§10 measured each)."""
    # Channel base ("top" in the reference): the channels of G's first encoder conv and of D's
    # first conv; the other layers' are multiples of it.
    base_channels: int = 64
    # Kernel size along time of every conv of G and D (odd: the padding keeps T).
    time_kernel: int = 5
    w_dim: int = 64
    z_dim: int = 64
    # Latent Transform init: "paper" (w ~ 2e-5 at init, as the reference) or "torch_default"
    # (w ~ 0.1: the style path gets gradient from the start; RESULTS §8).
    latent_init: LatentInit = "paper"
    # D's real/fake verdict also projects the style label (Miyato & Koyama 2018), so D judges a
    # walk *of that style*, not only through its class head (RESULTS §8).
    d_cond: bool = False
    # None: the paper's G; a WalkerConfig: the walker around it (the small presets).
    walker: WalkerConfig | None = None

    @property
    def gait_phase(self) -> bool:
        """Whether G keeps a gait clock (a walker with its gait phase on)."""
        return self.walker is not None and self.walker.gait_phase


@dataclasses.dataclass(frozen=True)
class ComputeConfig:
    """How the same parameters are computed: a run may resume or be evaluated with other values
    (checkpoints compare the model section only)."""
    # "fast" (nn/conv.py's rewrites, the faster form on CPU) or "xla" (the plain lax.conv form);
    # same function up to float rounding (tests/test_fast_equals_reference.py, docs/PERFORMANCE.md).
    conv_impl: ConvImpl = "fast"
    # Activation dtype of G and D; "bfloat16" is mixed precision for GPUs (parameters, optimizer
    # state, normalisation statistics and losses stay float32).
    compute_dtype: ComputeDtype = "float32"


@dataclasses.dataclass(frozen=True)
class TrainConfig:
    batch_size: int = 24
    num_steps: int = 200_000
    lr_g: float = 2e-4
    lr_d: float = 1e-4
    beta1: float = 0.5
    beta2: float = 0.999
    # Loss weights as in the paper (its data were in CMU units).
    w_g_adv: float = 1.0
    w_g_cls: float = 5.0
    w_g_curve: float = 0.1
    w_g_bone: float = 0.1
    # Gait terms (0 in the paper): G's stride against the style's measured stride
    # (model.gait_phase), the lower toe on the floor, toes near the floor still (losses.foot_losses).
    w_g_stride: float = 0.0
    w_g_floor: float = 0.0
    w_g_skate: float = 0.0
    # Step height (0 in the paper): each window's toe-height difference (left − right, its standard
    # deviation) against its style's measured on real clips, in log (losses.step_height_loss): the
    # skate term pays a moving toe to lift, and nothing else says how high (RESULTS §23).
    w_g_step_height: float = 0.0
    # Reconstruction (0 in the paper): the first half of each batch asks G for the real window's
    # own style at its measured gait phase and compares pose and root sway (L1), so that the
    # phase channels mean what the real feet do (losses.reconstruction_loss).
    w_g_rec: float = 0.0
    # The reconstructed half's z: "zero", or "sampled" (the same N(0, I) draw as the other half),
    # so that every z, not only the centre, must walk the window's style.
    rec_z: RecZ = "zero"
    # Root jerk (0 in the paper): how far the batch's mean squared second difference of G's root
    # velocity exceeds the real windows' (losses.root_jerk_excess): G may not plant a foot by
    # shaking the whole body.
    w_g_root_jerk: float = 0.0
    # Joint jerk (0 in the paper): how far each world joint's mean squared third difference exceeds
    # the same joint's in the real windows, summed over joints (losses.joint_jerk_excess).
    w_g_joint_jerk: float = 0.0
    w_d_adv: float = 1.0
    w_d_cls: float = 5.0
    # Number of points of the curve loss (paper: 4).
    curve_points: int = 4
    # "bce_prob" reproduces the reference (BCE on sigmoid/softmax probabilities);
    # "bce_logit" is the numerically stable form (the reference's blew up with the output prior).
    gan_loss: GanLoss = "bce_prob"
    seed: int = 0
    log_every: int = 100
    preview_every: int = 5000
    checkpoint_every: int = 20000
    keep_checkpoints: int = 3
    # Moving average of G's parameters for generation, evaluation and analysis (training never
    # reads it; checkpoint.load_run): 0 keeps none (the paper), 0.999 about the last 1,000 steps.
    g_ema_decay: float = 0.0


@dataclasses.dataclass(frozen=True)
class Config:
    name: str = "paper"
    data: DataConfig = DataConfig()
    model: ModelConfig = ModelConfig()
    train: TrainConfig = TrainConfig()
    compute: ComputeConfig = ComputeConfig()


SECTIONS = {"data": DataConfig, "model": ModelConfig, "train": TrainConfig, "compute": ComputeConfig}
# Optional sub-configs inside a section: (section, field) -> its dataclass (None when off)
SUBSECTIONS = {("model", "walker"): WalkerConfig}


def load_config(path: str | Path, check: bool = True) -> Config:
    """Import a configs/*.py file and call its `get_config()`; validate unless check=False
    (the command line validates after applying its overrides)."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"config file not found: {path}")
    spec = importlib.util.spec_from_file_location(f"_motiongan_config_{path.stem}", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    if not hasattr(module, "get_config"):
        raise ConfigError(f"{path} defines no get_config()")
    cfg = module.get_config()
    return validate(cfg) if check else cfg


def _parse_value(text: str, current: Any, field: str, nullable: bool = True) -> Any:
    if current is None or isinstance(current, str):
        if nullable and text.lower() in ("none", "null"):
            return None
        return text
    if isinstance(current, bool) and text.lower() in ("true", "false"):
        return text.lower() == "true"
    try:
        value = ast.literal_eval(text)
    except (ValueError, SyntaxError):
        raise ConfigError(f"{field}: cannot parse {text!r} as {type(current).__name__}") from None
    if isinstance(current, bool):
        if not isinstance(value, bool):
            raise ConfigError(f"{field}: expected True/False, got {text!r}")
    elif isinstance(current, int):
        if not isinstance(value, int) or isinstance(value, bool):
            raise ConfigError(f"{field}: expected an integer, got {text!r}")
    elif isinstance(current, float):
        if not isinstance(value, (int, float)) or isinstance(value, bool):
            raise ConfigError(f"{field}: expected a number, got {text!r}")
        value = float(value)
    elif isinstance(current, tuple):
        if isinstance(value, (str, int, float)):
            value = (value,)
        value = tuple(value)
    return value


def override(cfg: Config, assignments: list[str]) -> Config:
    """Apply `section.field=value` (or `name=value`) strings; unknown fields are errors."""
    for item in assignments:
        if "=" not in item:
            raise ConfigError(f"override {item!r} is not of the form field=value")
        key, text = item.split("=", 1)
        parts = key.strip().split(".")
        if len(parts) == 1 and parts[0] == "name":
            cfg = dataclasses.replace(cfg, name=text)
            continue
        if len(parts) == 3 and tuple(parts[:2]) in SUBSECTIONS:
            cfg = _override_sub(cfg, parts, text, key)
            continue
        if len(parts) == 2 and tuple(parts) in SUBSECTIONS:
            cfg = _override_sub_whole(cfg, parts, text, key)
            continue
        if len(parts) != 2 or parts[0] not in SECTIONS:
            raise ConfigError(f"unknown config field {key!r} (use data.X, model.X, train.X or compute.X)")
        section = getattr(cfg, parts[0])
        types = {f.name: str(f.type) for f in dataclasses.fields(section)}
        if parts[1] not in types:
            raise ConfigError(f"unknown config field {key!r}; {parts[0]} has: {', '.join(sorted(types))}")
        value = _parse_value(text, getattr(section, parts[1]), key, nullable="None" in types[parts[1]])
        cfg = dataclasses.replace(cfg, **{parts[0]: dataclasses.replace(section, **{parts[1]: value})})
    return cfg


def _override_sub(cfg: Config, parts: list[str], text: str, key: str) -> Config:
    """`model.walker.X=value`: one field of a sub-config (made with its defaults if it was off)."""
    section = getattr(cfg, parts[0])
    cls = SUBSECTIONS[tuple(parts[:2])]
    sub = getattr(section, parts[1]) or cls()
    types = {f.name: str(f.type) for f in dataclasses.fields(cls)}
    if parts[2] not in types:
        raise ConfigError(f"unknown config field {key!r}; {parts[0]}.{parts[1]} has: {', '.join(sorted(types))}")
    value = _parse_value(text, getattr(sub, parts[2]), key, nullable=False)
    sub = dataclasses.replace(sub, **{parts[2]: value})
    return dataclasses.replace(cfg, **{parts[0]: dataclasses.replace(section, **{parts[1]: sub})})


def _override_sub_whole(cfg: Config, parts: list[str], text: str, key: str) -> Config:
    """`model.walker=None` (off) or `model.walker=default` (on, every part at its default)."""
    if text.strip().lower() in ("none", "null", "off"):
        value = None
    elif text.strip().lower() in ("default", "on"):
        value = SUBSECTIONS[tuple(parts)]()
    else:
        raise ConfigError(f"{key}: None (off) or default (on), got {text!r}; set one part with {key}.FIELD=VALUE")
    section = getattr(cfg, parts[0])
    return dataclasses.replace(cfg, **{parts[0]: dataclasses.replace(section, **{parts[1]: value})})


def validate(cfg: Config, *, need_data: bool = True) -> Config:
    """`cfg` if every field is valid, else ConfigError naming the field. need_data=False accepts
    a config without the data directory its label rule needs (a dry run describes the model)."""
    d, m, t = cfg.data, cfg.model, cfg.train

    def need(ok: bool, field: str, msg: str) -> None:
        if not ok:
            raise ConfigError(f"{field}: {msg}")

    checked = [(name, cls, getattr(cfg, name)) for name, cls in SECTIONS.items()]
    checked += [(f"{s}.{f}", cls, getattr(getattr(cfg, s), f)) for (s, f), cls in SUBSECTIONS.items()
                if getattr(getattr(cfg, s), f) is not None]
    for section_name, cls, section in checked:  # the Literal and bool options, from their types
        for name, kind in get_type_hints(cls).items():
            value, field = getattr(section, name), f"{section_name}.{name}"
            if get_origin(kind) is Literal:
                need(value in get_args(kind), field, f"{value!r} is not one of {', '.join(get_args(kind))}")
            elif kind is bool:
                need(isinstance(value, bool), field, f"true or false, got {value!r}")

    need(d.data_dir is None or Path(d.data_dir).is_dir(), "data.data_dir",
         f"data directory {d.data_dir!r} does not exist")
    need(d.frame_step >= 1, "data.frame_step", "must be >= 1")
    need(d.frame_nums % d.frame_step == 0, "data.frame_nums", "must be a multiple of data.frame_step")
    need(d.window_T % 8 == 0 and d.window_T >= 16, "data.frame_nums",
         f"window length T = frame_nums // frame_step = {d.window_T} must be a multiple of 8 and >= 16")
    need(d.control_point_interval >= 2, "data.control_point_interval", "must be >= 2")
    need(d.window_stride >= 1, "data.window_stride", "must be >= 1")
    need(d.start_offset >= 0, "data.start_offset", "must be >= 0")
    need(len(d.fps_factors) >= 1 and all(f > 0 for f in d.fps_factors), "data.fps_factors", "must be positive")
    need(d.curve_noise >= 0, "data.curve_noise", "must be >= 0")
    need(d.units_to_m is None or d.units_to_m > 0, "data.units_to_m", "must be positive")
    need(d.val_modulus == 0 or (d.val_modulus >= 2 and 0 <= d.val_remainder < d.val_modulus),
         "data.val_modulus", "need 0 (no split) or modulus >= 2 with 0 <= remainder < modulus")
    need(d.data_dir is not None or d.label_rule == "synthetic" or not need_data, "data.data_dir",
         f"label rule {d.label_rule!r} needs a data directory (--data DIR); only 'synthetic' has a default")
    need(len(set(d.styles)) == len(d.styles), "data.styles", "duplicate style names")
    need(m.base_channels >= 1, "model.base_channels", "must be a positive integer")
    need(m.time_kernel >= 1 and m.time_kernel % 2 == 1, "model.time_kernel", "must be odd")
    need(m.w_dim >= 1 and m.z_dim >= 1, "model.w_dim", "w_dim and z_dim must be positive")
    need(t.batch_size >= 1, "train.batch_size", "must be >= 1")
    need(t.num_steps >= 1, "train.num_steps", "must be >= 1")
    need(t.lr_g > 0 and t.lr_d > 0, "train.lr_g", "learning rates must be positive")
    need(0 <= t.beta1 < 1 and 0 <= t.beta2 < 1, "train.beta1", "betas must be in [0, 1)")
    need(t.curve_points >= 1 and d.window_T % t.curve_points == 0, "train.curve_points",
         "must divide the window length T")
    need(t.log_every >= 1 and t.checkpoint_every >= 1 and t.preview_every >= 0, "train.log_every",
         "log/checkpoint intervals must be >= 1")
    need(0.0 <= t.g_ema_decay < 1.0, "train.g_ema_decay", "must be in [0, 1) (0: no average)")
    for name in (f"w_g_{n}" for n in ("stride", "floor", "skate", "step_height", "rec", "root_jerk", "joint_jerk")):
        need(getattr(t, name) >= 0, f"train.{name}", "loss weights must be >= 0")
    need(m.walker is None or isinstance(m.walker, WalkerConfig), "model.walker", "None or a WalkerConfig")
    need(t.w_g_stride == 0 or m.gait_phase, "train.w_g_stride",
         "needs model.walker.gait_phase (a stride head to train)")
    need(t.w_g_rec == 0 or m.gait_phase, "train.w_g_rec", "needs model.walker.gait_phase (a phase to reconstruct at)")
    need(m.walker is None or not m.walker.stride_speed or m.walker.gait_phase, "model.walker.stride_speed",
         "needs model.walker.gait_phase (a stride head to follow the speed)")
    need(t.w_g_rec == 0 or t.batch_size >= 2, "train.w_g_rec", "needs train.batch_size >= 2 (half is reconstructed)")
    need(t.rec_z == "zero" or t.w_g_rec > 0, "train.rec_z", "needs train.w_g_rec > 0 (a half to reconstruct)")
    need(t.keep_checkpoints >= 1, "train.keep_checkpoints", "must be >= 1")
    return cfg


# ---------------------------------------------------------------------------------------------
# Saved configs: the one map from older schemas to this one
# ---------------------------------------------------------------------------------------------

# The saved form's schema: 2 since model.walker, 3 since walker.stride_speed on by default (Dec 7);
# configs saved before model.walker carry no number and are schema 1. `upgrade` reads every
# schema from OLDEST_SCHEMA on.
SCHEMA = 3
OLDEST_SCHEMA = 1

# Options that no longer exist, with the only value any preset used: a saved config holding that
# value loads without them; one that used another value is refused (docs/RESULTS.md, "Retired
# options", keeps their record).
RETIRED = {
    "model": {"phase_wavelengths_m": (), "use_z": "transform", "d_frame": "world",
              "length_unit": 0.056444},  # representation.LENGTH_UNIT_M (config imports nothing of the package)
    "data": {"augment_fps": True},
}
# String options that became booleans: old value -> new value.
BOOLEANISED = {
    "model": {"output_prior": {"none": False, "rest_and_curve": True},
              "d_cond": {"none": False, "projection": True}},
}
# Fields that moved to another section or took a clearer name: (old section, old name) -> (section, name).
MOVED = {("model", "conv_impl"): ("compute", "conv_impl"), ("model", "compute_dtype"): ("compute", "compute_dtype"),
         ("model", "top"): ("model", "base_channels"), ("model", "kw"): ("model", "time_kernel")}
# The walker's parts were flat model fields before they became model.walker: old name -> new name
# (each was off at its default: a saved model section with all of them off is the paper's G).
WALKER_FIELDS = {"output_prior": "output_prior", "g_frame": "frame", "exact_bones": "exact_bones",
                 "gait_phase": "gait_phase", "root_height": "root_height"}
WALKER_OFF = {"output_prior": False, "frame": "world", "exact_bones": False, "gait_phase": False, "root_height": False,
              "stride_speed": False}
# Presets that were renamed: old config name -> new.
RENAMED_PRESETS = {"cpu": "small", "bandai_cpu": "bandai_small"}


def upgrade(d: dict) -> dict:
    """A saved config dict (to_dict's form) of any schema from OLDEST_SCHEMA (1: every config saved
    before Dec 7, which has no "schema" entry) to SCHEMA, in this version's schema: retired options
    at their only value dropped, string options that became booleans mapped, moved or renamed
    fields in their new place, the walker's flat fields as model.walker, renamed presets under
    their new name. ConfigError for a saved config that used a retired option, an old string value
    that has no boolean, or a schema this version does not know."""
    schema = d.get("schema", 1)
    if not isinstance(schema, int) or not OLDEST_SCHEMA <= schema <= SCHEMA:
        raise ConfigError(f"saved config of schema {schema!r}: this version reads schemas {OLDEST_SCHEMA} to "
                          f"{SCHEMA} (a newer version of motiongan_jax wrote it?)")
    out = {k: (dict(v) if isinstance(v, dict) else v) for k, v in d.items() if k != "schema"}
    out["name"] = RENAMED_PRESETS.get(out.get("name"), out.get("name", "restored"))
    for (section, name), (new_section, new_name) in MOVED.items():
        values = out.get(section, {})
        if name in values:
            out.setdefault(new_section, {}).setdefault(new_name, values.pop(name))
    for section, retired in RETIRED.items():
        values = out.get(section, {})
        for name, only in retired.items():
            if name in values:
                value = values.pop(name)
                if (tuple(value) if isinstance(value, list) else value) != only:
                    raise ConfigError(f"{section}.{name} = {value!r}: this option no longer exists "
                                      "(retrain with the current code)")
    for section, fields in BOOLEANISED.items():
        values = out.get(section, {})
        for name, mapping in fields.items():
            if isinstance(values.get(name), str):
                if values[name] not in mapping:
                    raise ConfigError(f"{section}.{name} = {values[name]!r}: not a value it ever had")
                values[name] = mapping[values[name]]
    model = out.get("model", {})
    if any(name in model for name in WALKER_FIELDS):
        parts = {**WALKER_OFF, **{new: model.pop(old) for old, new in WALKER_FIELDS.items() if old in model}}
        model["walker"] = None if parts == WALKER_OFF else parts
    if schema < 3 and isinstance(model.get("walker"), dict):
        # Schema 3 turned stride_speed on by default; a walker saved before it had no such part.
        model["walker"].setdefault("stride_speed", False)
    return out


def from_dict(d: dict) -> Config:
    """Inverse of to_dict (lists become tuples again), for configs saved by this or any earlier
    version (`upgrade`); unknown keys are errors, missing fields take their defaults."""
    d = upgrade(d)

    def section(name, cls, values=None):
        values = d.get(name, {}) if values is None else values
        unknown = set(values) - {f.name for f in dataclasses.fields(cls)}
        if unknown:
            raise ConfigError(f"unknown {cls.__name__} field(s): {', '.join(sorted(unknown))}")
        values = {k: tuple(v) if isinstance(v, list) else v for k, v in values.items()}
        for (s, f), sub_cls in SUBSECTIONS.items():
            if s == name and isinstance(values.get(f), dict):
                values[f] = section(f"{s}.{f}", sub_cls, values[f])
        return cls(**values)

    unknown = set(d) - set(SECTIONS) - {"name"}
    if unknown:
        raise ConfigError(f"unknown config entries: {', '.join(sorted(unknown))}")
    return Config(name=d["name"], **{name: section(name, cls) for name, cls in SECTIONS.items()})


def to_dict(cfg: Config) -> dict:
    """The saved form: every field, and the schema it is written in."""
    return {"schema": SCHEMA, **dataclasses.asdict(cfg)}


def config_hash(cfg: Config | dict) -> str:
    """Short stable hash of every field: names a config in reports and caches. A dict is hashed
    as saved (a provenance record written by an older version keeps its hash)."""
    blob = json.dumps(cfg if isinstance(cfg, dict) else to_dict(cfg), sort_keys=True, default=str).encode()
    return hashlib.sha256(blob).hexdigest()[:12]


# ---------------------------------------------------------------------------------------------
# Named presets (configs/*.py load these; docs/RESULTS.md measured the small ones)
# ---------------------------------------------------------------------------------------------


def paper() -> Config:
    """Exactly the paper: CMU styled walks (subjects 137 and 142), 28 styles, B 24, T 128, 200k
    steps. The CMU trials are not shipped (pass --data DIR, files named like 137_04.bvh); far too
    slow for a CPU (its step time: docs/PERFORMANCE.md): run it on a GPU."""
    return Config(
        name="paper",
        data=DataConfig(label_rule="cmu", styles=PAPER_STYLES, start_offset=1, control_point_interval=256,
                        frame_nums=1024, frame_step=8, window_stride=3, val_modulus=0),
        model=ModelConfig(base_channels=64, time_kernel=5, w_dim=64, z_dim=64),
        train=TrainConfig(batch_size=24, num_steps=200_000, log_every=100, preview_every=5000,
                          checkpoint_every=20_000),
    )


def bandai() -> Config:
    """The paper's architecture on the Bandai Namco data (30 fps, centimetres, 20 joints): a step
    of 2 gives the paper's 15 Hz, T 64 a 4.3 s window, control points the paper's ~2.1 s apart.
    Pass --data DIR (dataset-1, dataset-2 or their parent)."""
    return Config(
        name="bandai",
        data=DataConfig(label_rule="bandai", units_to_m=0.01, start_offset=0, control_point_interval=64,
                        frame_nums=128, frame_step=2, window_stride=1, val_modulus=4, val_remainder=0),
        model=ModelConfig(base_channels=64, time_kernel=5, w_dim=64, z_dim=64),
        train=TrainConfig(batch_size=24, num_steps=100_000, log_every=100, preview_every=5000,
                          checkpoint_every=10_000),
    )


def small() -> Config:
    """A smaller model that learns to walk in styles on 2 CPU cores (7,000 steps; the README gives
    its training time), on the embedded dataset (60 fps: a step of 4 gives 15 Hz, T 32 a 2.1 s
    window); the shipped model. Narrower (16 base channels) and with the departures from the paper
    that made it learn, each measured in docs/RESULTS.md (its "The small preset" paragraph lists
    them by §)."""
    return Config(
        name="small",
        data=DataConfig(label_rule="synthetic", start_offset=1, control_point_interval=128, frame_nums=128,
                        frame_step=4, window_stride=2, val_modulus=5, val_remainder=0),
        model=ModelConfig(base_channels=16, time_kernel=5, w_dim=32, z_dim=32, latent_init="torch_default",
                          d_cond=True, walker=WalkerConfig()),
        train=TrainConfig(batch_size=16, num_steps=7000, lr_d=2e-5, gan_loss="bce_logit", g_ema_decay=0.999,
                          w_g_stride=1.0, w_g_floor=5.0, w_g_skate=5.0, w_g_rec=5.0, w_g_root_jerk=1.0,
                          w_g_joint_jerk=1.0, rec_z="sampled", log_every=50, preview_every=2000, checkpoint_every=1000,
                          keep_checkpoints=10),
    )


def bandai_small() -> Config:
    """`small`'s model and training on `bandai`'s data, with T 32 (a 2.1 s window at 15 Hz)."""
    b, s = bandai(), small()
    return dataclasses.replace(b, name="bandai_small", data=dataclasses.replace(b.data, frame_nums=64),
                               model=s.model, train=s.train)


def tiny() -> Config:
    """Tests only: the smallest shapes that exercise every layer (T 16, 4 base channels, batch 2)."""
    return Config(
        name="tiny",
        data=DataConfig(label_rule="synthetic", start_offset=1, control_point_interval=32, frame_nums=64,
                        frame_step=4, window_stride=8, val_modulus=5, val_remainder=0),
        model=ModelConfig(base_channels=4, time_kernel=5, w_dim=8, z_dim=8),
        train=TrainConfig(batch_size=2, num_steps=4, log_every=1, preview_every=0, checkpoint_every=2,
                          keep_checkpoints=2),
    )


PRESETS = {f.__name__: f for f in (paper, bandai, small, bandai_small, tiny)}


def preset(name: str) -> Config:
    """The named preset's config (not validated: the real-data presets need --data)."""
    if name not in PRESETS:
        raise ConfigError(f"unknown preset {name!r}; one of {', '.join(PRESETS)}")
    return PRESETS[name]()
