"""Configs as data: one frozen dataclass tree, four sizes in configs/*.py.

Every field can be overridden from the command line with `--set section.field=value`
(see `override`). `validate` rejects bad values before anything is compiled.
"""

from __future__ import annotations

import ast
import dataclasses
import hashlib
import importlib.util
import json
from pathlib import Path
from typing import Any

LABEL_RULES = ("paper", "bandai", "bandai_session", "cmu", "synthetic")
GAN_LOSSES = ("bce_prob", "bce_logit")


class ConfigError(ValueError):
    """A config value is invalid; the message names the field."""


@dataclasses.dataclass(frozen=True)
class DataConfig:
    # BVH directory; None trains on the embedded default (procedural) dataset.
    data_dir: str | None = None
    # How style labels are read from file names: paper `<Style>_*.bvh`, bandai
    # `dataset-N_<content>_<style>_<trial>.bvh`, cmu `<subject>_<trial>.bvh` via the shipped table,
    # synthetic: the embedded dataset's own names (same shape as paper).
    label_rule: str = "synthetic"
    # Style names in label-index order; empty means "every style found, sorted".
    styles: tuple[str, ...] = ()
    # Metres per file unit; None infers it from the label rule (cmu/paper 0.056444, bandai 0.01).
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
    # FPS augmentation: playback-speed factors drawn uniformly (paper: 0.5, 1, 1.5).
    augment_fps: bool = True
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


OUTPUT_PRIORS = ("none", "rest_and_curve")
G_FRAMES = ("world", "curve")
D_FRAMES = ("world", "window")
D_CONDS = ("none", "projection")


@dataclasses.dataclass(frozen=True)
class ModelConfig:
    # Channel base ("top" in the reference): G's first conv width, D's first conv width.
    top: int = 64
    # Kernel width along time.
    kw: int = 5
    w_dim: int = 64
    z_dim: int = 64
    # Where z comes from: "transform" (N(0, I) through the Latent Transform), "zeros".
    use_z: str = "transform"
    # Latent Transform init: "paper" (w ~ 2e-5 at init, as the reference) or "torch_default"
    # (w ~ 0.1: the style path gets gradient from the start; for short runs).
    latent_init: str = "paper"
    # The networks' unit of length, in metres. Data stay in metres outside; G and D see lengths
    # divided by this, and the curve and bone losses are measured in it. The paper's data were in
    # CMU units (0.056444 m): in metres G's first instance norm would see variances near its
    # epsilon (1e-8), and the loss weights would change their balance.
    length_unit: float = 0.056444
    # "none": the paper's G, whose heads start near zero (a collapsed skeleton standing still) and
    # need thousands of steps to reach the data's scale. "rest_and_curve" (small configs): the
    # pose head adds the skeleton's rest pose and the root-velocity head adds the input curve's
    # velocity, so G starts from a skeleton of the right size moving along the curve and learns
    # the differences. Same parameters; not the paper's network.
    output_prior: str = "none"
    # The frame G works in: "world" (the paper: G must learn to turn the body to the path for every
    # direction the rotation augmentation draws) or "curve" (small configs: G sees the curve from
    # the walker's heading and its motion is turned to the path's smoothed heading; exactly
    # equivariant to rotations about +y; nn/generator.py). Same parameters.
    g_frame: str = "world"
    # True (small configs): G's bones take the skeleton's lengths exactly, keeping the directions
    # G outputs (nn/generator.py project_bones); False: the paper, only the bone loss. Same parameters.
    exact_bones: bool = False
    # The frame D judges in: "world" (the paper) or "window" (small configs: each window turned so
    # that its travel points along +z, the evaluator's frame; nn/discriminator.py). Same parameters.
    d_frame: str = "world"
    # What D's real/fake verdict sees of the style: "none" (the paper: an unconditional verdict;
    # the style enters only through the class head, trained on real windows) or "projection"
    # (small configs: the verdict also adds <V[label], features>, Miyato & Koyama 2018, so D judges
    # whether a window is a real walk *of that style*; fakes are judged with the label G was asked
    # for). Adds one spectral-norm linear map (8·top·T/16 -> styles) to D.
    d_cond: str = "none"
    # True (small configs): G keeps a clock in walked distance, φ = φ0 + 2π s / λ(w), with a stride
    # length λ(w) learned from the strides measured on the real training clips, and sees sin and
    # cos of φ and 2φ at its input and every decoder level (nn/generator.py); False: the paper's G.
    gait_phase: bool = False
    # True (small configs): G's root head gives the root's height, not its vertical velocity, so
    # the body cannot drift off the floor along a long curve; False: the paper's G.
    root_height: bool = False
    # How G and D compute their convolutions: "fast" (nn/conv.py: skip and polyphase rewrites,
    # matrix-product weight gradients; the faster form on CPU) or "xla" (the straightforward
    # lax.conv form). Same parameters and checkpoints, same function up to float rounding
    # (tests/test_fast_equals_reference.py); see docs/PERFORMANCE.md.
    conv_impl: str = "fast"
    # Activation dtype of G and D: "float32" or "bfloat16" (mixed precision, meant for GPUs:
    # parameters, optimizer state, normalisation statistics and losses stay float32).
    compute_dtype: str = "float32"


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
    # Gait terms (small configs; 0 in the paper): G's stride length against the style's measured
    # stride (model.gait_phase), the lower toe on the floor, and toes near the floor standing
    # still (losses.foot_losses); the contact height is calibrated on the real training clips.
    w_g_stride: float = 0.0
    w_g_floor: float = 0.0
    w_g_skate: float = 0.0
    # Reconstruction (small configs; 0 in the paper): for the first half of each batch G is asked
    # for the real window's own style (any z) at the gait phase measured on it (data.clip_gait_phase)
    # and its pose and root sway are compared with the window's (L1, losses.reconstruction_loss),
    # so the phase channels mean what the real feet do; the other half is the arbitrary pairing.
    w_g_rec: float = 0.0
    w_d_adv: float = 1.0
    w_d_cls: float = 5.0
    # Number of points of the curve loss (paper: 4).
    curve_points: int = 4
    # "bce_prob" reproduces the reference (BCE on sigmoid/softmax probabilities);
    # "bce_logit" is the numerically stable form.
    gan_loss: str = "bce_prob"
    seed: int = 0
    log_every: int = 100
    preview_every: int = 5000
    checkpoint_every: int = 20000
    keep_checkpoints: int = 3
    # Exponential moving average of G's parameters, used for generation, evaluation and analysis
    # (checkpoint.load_run; training itself never reads it). 0 keeps none (the paper); e.g. 0.999
    # averages over about the last 1,000 steps, against G's step-to-step oscillation (at the cpu
    # size: style accuracy level with the raw G, lower FMD; docs/RESULTS.md §7).
    g_ema_decay: float = 0.0


@dataclasses.dataclass(frozen=True)
class Config:
    name: str = "paper"
    data: DataConfig = DataConfig()
    model: ModelConfig = ModelConfig()
    train: TrainConfig = TrainConfig()


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
        # "none" is a value of some string options (model.output_prior, model.d_cond), so it
        # means None only where the field may be None
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
        if len(parts) != 2 or parts[0] not in ("data", "model", "train"):
            raise ConfigError(f"unknown config field {key!r} (use data.X, model.X or train.X)")
        section = getattr(cfg, parts[0])
        types = {f.name: str(f.type) for f in dataclasses.fields(section)}
        if parts[1] not in types:
            raise ConfigError(f"unknown config field {key!r}; {parts[0]} has: {', '.join(sorted(types))}")
        value = _parse_value(text, getattr(section, parts[1]), key, nullable="None" in types[parts[1]])
        cfg = dataclasses.replace(cfg, **{parts[0]: dataclasses.replace(section, **{parts[1]: value})})
    return cfg


def validate(cfg: Config, *, need_data: bool = True) -> Config:
    """`cfg` if every field is valid, else ConfigError naming the field. need_data=False accepts
    a config without the data directory its label rule needs (a dry run describes the model)."""
    d, m, t = cfg.data, cfg.model, cfg.train

    def need(ok: bool, field: str, msg: str) -> None:
        if not ok:
            raise ConfigError(f"{field}: {msg}")

    need(d.label_rule in LABEL_RULES, "data.label_rule", f"unknown style rule {d.label_rule!r}; one of {LABEL_RULES}")
    need(d.data_dir is None or Path(d.data_dir).is_dir(), "data.data_dir", f"data directory {d.data_dir!r} does not exist")
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
    need(m.top >= 1 and m.top % 1 == 0, "model.top", "must be a positive integer")
    need(m.kw >= 1 and m.kw % 2 == 1, "model.kw", "must be odd")
    need(m.w_dim >= 1 and m.z_dim >= 1, "model.w_dim", "w_dim and z_dim must be positive")
    need(m.use_z in ("transform", "zeros"), "model.use_z", "one of transform, zeros")
    need(m.latent_init in ("paper", "torch_default"), "model.latent_init", "one of paper, torch_default")
    need(m.output_prior in OUTPUT_PRIORS, "model.output_prior", f"one of {', '.join(OUTPUT_PRIORS)}")
    need(isinstance(m.exact_bones, bool), "model.exact_bones", "true or false")
    need(m.g_frame in G_FRAMES, "model.g_frame", f"one of {', '.join(G_FRAMES)}")
    need(isinstance(m.gait_phase, bool), "model.gait_phase", "true or false")
    need(isinstance(m.root_height, bool), "model.root_height", "true or false")
    need(m.d_frame in D_FRAMES, "model.d_frame", f"one of {', '.join(D_FRAMES)}")
    need(m.d_cond in D_CONDS, "model.d_cond", f"one of {', '.join(D_CONDS)}")
    need(m.conv_impl in ("fast", "xla"), "model.conv_impl", "one of fast, xla")
    need(m.compute_dtype in ("float32", "bfloat16"), "model.compute_dtype", "one of float32, bfloat16")
    need(t.batch_size >= 1, "train.batch_size", "must be >= 1")
    need(t.num_steps >= 1, "train.num_steps", "must be >= 1")
    need(t.lr_g > 0 and t.lr_d > 0, "train.lr_g", "learning rates must be positive")
    need(0 <= t.beta1 < 1 and 0 <= t.beta2 < 1, "train.beta1", "betas must be in [0, 1)")
    need(m.length_unit > 0, "model.length_unit", "must be positive")
    need(t.curve_points >= 1 and d.window_T % t.curve_points == 0, "train.curve_points",
         "must divide the window length T")
    need(t.gan_loss in GAN_LOSSES, "train.gan_loss", f"one of {GAN_LOSSES}")
    need(t.log_every >= 1 and t.checkpoint_every >= 1 and t.preview_every >= 0, "train.log_every",
         "log/checkpoint intervals must be >= 1")
    need(0.0 <= t.g_ema_decay < 1.0, "train.g_ema_decay", "must be in [0, 1) (0: no average)")
    for name in ("w_g_stride", "w_g_floor", "w_g_skate", "w_g_rec"):
        need(getattr(t, name) >= 0, f"train.{name}", "loss weights must be >= 0")
    need(t.w_g_stride == 0 or m.gait_phase, "train.w_g_stride", "needs model.gait_phase (a stride head to train)")
    need(t.w_g_rec == 0 or m.gait_phase, "train.w_g_rec", "needs model.gait_phase (a phase to reconstruct at)")
    need(t.w_g_rec == 0 or t.batch_size >= 2, "train.w_g_rec", "needs train.batch_size >= 2 (half is reconstructed)")
    need(t.keep_checkpoints >= 1, "train.keep_checkpoints", "must be >= 1")
    return cfg


# Options that no longer exist, with the value that meant "off": a saved config holding that value
# loads without them; one that used the option is refused (docs/RESULTS.md keeps their record).
RETIRED_FIELDS = {"model": {"phase_wavelengths_m": ()}}


def _drop_retired(section_name: str, values: dict) -> dict:
    out = dict(values)
    for name, off in RETIRED_FIELDS.get(section_name, {}).items():
        if name in out:
            value = out.pop(name)
            if (tuple(value) if isinstance(value, list) else value) != off:
                raise ConfigError(f"{section_name}.{name} = {value!r}: this option no longer exists "
                                  "(retrain with the current code)")
    return out


def from_dict(d: dict) -> Config:
    """Inverse of to_dict (lists become tuples again); unknown keys are errors, retired options
    (RETIRED_FIELDS) are dropped when off."""
    def section(cls, values):
        values = _drop_retired({DataConfig: "data", ModelConfig: "model", TrainConfig: "train"}[cls], values)
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = set(values) - names
        if unknown:
            raise ConfigError(f"unknown {cls.__name__} field(s): {', '.join(sorted(unknown))}")
        return cls(**{k: tuple(v) if isinstance(v, list) else v for k, v in values.items()})

    return Config(name=d.get("name", "restored"), data=section(DataConfig, d.get("data", {})),
                  model=section(ModelConfig, d.get("model", {})), train=section(TrainConfig, d.get("train", {})))


def to_dict(cfg: Config) -> dict:
    return dataclasses.asdict(cfg)


def config_hash(cfg: Config) -> str:
    """Short stable hash of every field: names a config in reports and caches."""
    blob = json.dumps(to_dict(cfg), sort_keys=True, default=str).encode()
    return hashlib.sha256(blob).hexdigest()[:12]
