"""The embedded default dataset: procedural styled walks on a CMU-topology skeleton.

Training uses this when no data directory is given, so a fresh clone can train at once. Every
style has known gait parameters (`GaitParams`), so the learned style space can be checked later
(e.g. a linear probe from w to the parameters). Everything here is our own: the skeleton has
CMU's joint names, order, channels and zero-length joints (so the paper's 28-joint / 81-row
representation applies unchanged) but its own round-number bone lengths.

Conventions (the same as CMU files):
- Units: CMU units, 1 unit = 0.056444 m (`UNITS_TO_M`). Internally everything is in metres and
  converted when the channels are written.
- Y up, floor = X-Z plane. At zero rotation the character faces +Z and its left side is +X.
- Channels: root Xposition Yposition Zposition Zrotation Yrotation Xrotation, every other joint
  Zrotation Yrotation Xrotation (intrinsic, R = Rz Ry Rx), degrees.
- Frame 0 is a T-pose (all rotations zero), like CMU trials; data.start_offset = 1 drops it.

How a walk is made (`generate_clip`):
1. Per-clip jitter: each gait parameter is scaled by (1 + 0.04 n), n ~ N(0, 1) clipped to +-2
   (`clip_params` returns the clip's actual parameters; styles.json lists them per file).
2. Path: the root's floor path has constant speed v = stride_length * cadence / 2 (m/s; a stride
   is two steps, cadence is steps per second). Its heading integrates a random curvature along
   arc length: a few gentle sinusoidal components (radius mostly > 5 m) plus occasional sharp
   turns (Gaussian curvature bumps of 45-120 degrees over ~1-2 m, about one per 12 m). Root yaw
   = path tangent (+ a small pelvis twist). The path passes through the origin at t = 0.
3. Gait phase: stride frequency f = cadence / 2; left leg phase u, right leg u + 0.5. Each foot
   has a stance fraction (0.55-0.68, shorter when faster) with a heel rocker, a flat foot, a
   forefoot rocker (heel rises, the foot rolls over the ball, toes flat) and a push-off (the
   ball rises, pivoting on the toe tip), then a swing phase. Stance feet are planted in the
   world (no skating): the flat foot lies where the body is at 35% of the stance, offset
   sideways by half the step width, toes out 7 degrees. The swing ankle moves along a
   minimum-jerk path from toe-off to the next heel strike, lifted by `foot_lift`.
4. Pelvis: twist, obliquity, lateral sway toward the stance foot, a forward tilt (part of the
   torso lean). Height: the soft minimum of (a) the crouch-dependent standing height minus the
   bounce curve (vertical_bounce * (1 - cos) / 2, lowest at the double supports), (b) the
   smooth lower envelope of what both legs can reach, and (c) the bounce curve lowered as a
   whole until it fits under (b), so that the pelvis excursion is vertical_bounce even where
   the stride alone would make it larger.
5. Legs by analytic two-link IK (hip abduction Z, hip flexion X, knee X; ankle orientation
   solved so the foot has its planned yaw and pitch; the toe joint keeps the toes flat).
6. Upper body: spine lean and counter-rotation, head tilt, counter-phase arm swing with elbow
   bend, arms hanging toward the vertical.
7. Floor: forward kinematics (kinematics.world_positions) gives the lowest foot point per
   frame; the root is moved down by that height (a running minimum over ~0.1 s, lightly
   smoothed, never more than the frame's own height, so smoothing never sinks a foot). With
   the planted feet above this is a safety net: the correction is ~0.
"""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
import tempfile
import zlib
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from scipy.ndimage import gaussian_filter1d, minimum_filter1d
from scipy.spatial.transform import Rotation

from motiongan_jax.cache import cache_root
from motiongan_jax.motion.bvh import Motion, Skeleton, write_bvh
from motiongan_jax.motion.representation import CMU_UNIT_M

# Bump whenever generation changes what it writes: it names the cache directory.
VERSION = "1"
UNITS_TO_M = CMU_UNIT_M
UNITS = f"CMU units (1 unit = {CMU_UNIT_M} m), Y up, character faces +Z at zero rotation"

# ----------------------------------------------------------------------------------------------
# Skeleton
# ----------------------------------------------------------------------------------------------

_ROOT_CHANNELS = ("Xposition", "Yposition", "Zposition", "Zrotation", "Yrotation", "Xrotation")
_ROT_CHANNELS = ("Zrotation", "Yrotation", "Xrotation")

# Our own bone lengths (CMU units). Leg: pelvis drop 1.5, thigh 7.5, shin 7.2, ankle height 1.0
# -> hip height 17.2 units (0.97 m). Legs hang straight down at zero rotation.
_HIP = (1.7, -1.5, 0.4)  # LeftUpLeg from the pelvis
_THIGH = 7.5
_SHIN = 7.2
_TOE = (0.0, -1.0, 2.0)  # LeftToeBase (ball of the foot) from the ankle
_TOE_END = 1.1
_HEEL = (0.0, -1.0, -0.8)  # virtual heel point (not a joint) from the ankle, for the heel rocker
_SPINE = 2.4
_SPINE1 = 2.4
_NECK1 = 1.8
_HEAD = 1.6
_HEAD_END = 1.8
_CLAVICLE = (3.2, 1.0, -0.2)  # LeftArm from Spine1
_UPPER_ARM = 5.0
_FOREARM = 4.3
_HAND = 0.7
_HAND_END = 0.6
_THUMB_END = 0.5

# (name, parent name, offset, has channels); depth-first CMU order. "_EndSite" joints are End Sites.
_JOINTS: tuple[tuple[str, str | None, tuple[float, float, float], bool], ...] = (
    ("Hips", None, (0.0, 0.0, 0.0), True),
    ("LHipJoint", "Hips", (0.0, 0.0, 0.0), True),
    ("LeftUpLeg", "LHipJoint", _HIP, True),
    ("LeftLeg", "LeftUpLeg", (0.0, -_THIGH, 0.0), True),
    ("LeftFoot", "LeftLeg", (0.0, -_SHIN, 0.0), True),
    ("LeftToeBase", "LeftFoot", _TOE, True),
    ("LeftToeBase_EndSite", "LeftToeBase", (0.0, 0.0, _TOE_END), False),
    ("RHipJoint", "Hips", (0.0, 0.0, 0.0), True),
    ("RightUpLeg", "RHipJoint", (-_HIP[0], _HIP[1], _HIP[2]), True),
    ("RightLeg", "RightUpLeg", (0.0, -_THIGH, 0.0), True),
    ("RightFoot", "RightLeg", (0.0, -_SHIN, 0.0), True),
    ("RightToeBase", "RightFoot", _TOE, True),
    ("RightToeBase_EndSite", "RightToeBase", (0.0, 0.0, _TOE_END), False),
    ("LowerBack", "Hips", (0.0, 0.0, 0.0), True),
    ("Spine", "LowerBack", (0.0, _SPINE, 0.0), True),
    ("Spine1", "Spine", (0.0, _SPINE1, 0.0), True),
    ("Neck", "Spine1", (0.0, 0.0, 0.0), True),
    ("Neck1", "Neck", (0.0, _NECK1, 0.1), True),
    ("Head", "Neck1", (0.0, _HEAD, 0.0), True),
    ("Head_EndSite", "Head", (0.0, _HEAD_END, 0.0), False),
    ("LeftShoulder", "Spine1", (0.0, 0.0, 0.0), True),
    ("LeftArm", "LeftShoulder", _CLAVICLE, True),
    ("LeftForeArm", "LeftArm", (_UPPER_ARM, 0.0, 0.0), True),
    ("LeftHand", "LeftForeArm", (_FOREARM, 0.0, 0.0), True),
    ("LeftFingerBase", "LeftHand", (0.0, 0.0, 0.0), True),
    ("LeftHandIndex1", "LeftFingerBase", (_HAND, 0.0, 0.0), True),
    ("LeftHandIndex1_EndSite", "LeftHandIndex1", (_HAND_END, 0.0, 0.0), False),
    ("LThumb", "LeftHand", (0.0, 0.0, 0.0), True),
    ("LThumb_EndSite", "LThumb", (_THUMB_END, 0.0, _THUMB_END), False),
    ("RightShoulder", "Spine1", (0.0, 0.0, 0.0), True),
    ("RightArm", "RightShoulder", (-_CLAVICLE[0], _CLAVICLE[1], _CLAVICLE[2]), True),
    ("RightForeArm", "RightArm", (-_UPPER_ARM, 0.0, 0.0), True),
    ("RightHand", "RightForeArm", (-_FOREARM, 0.0, 0.0), True),
    ("RightFingerBase", "RightHand", (0.0, 0.0, 0.0), True),
    ("RightHandIndex1", "RightFingerBase", (-_HAND, 0.0, 0.0), True),
    ("RightHandIndex1_EndSite", "RightHandIndex1", (-_HAND_END, 0.0, 0.0), False),
    ("RThumb", "RightHand", (0.0, 0.0, 0.0), True),
    ("RThumb_EndSite", "RThumb", (-_THUMB_END, 0.0, _THUMB_END), False),
)

JOINT_NAMES: tuple[str, ...] = tuple(j[0] for j in _JOINTS)
_IDX = {n: i for i, n in enumerate(JOINT_NAMES)}


def cmu_skeleton() -> Skeleton:
    """CMU's 31-joint hierarchy (+ 7 End Sites = 38 joints) with our own bone lengths, CMU units."""
    parents = tuple(-1 if p is None else _IDX[p] for _, p, _, _ in _JOINTS)
    offsets = np.array([o for _, _, o, _ in _JOINTS], dtype=np.float64)
    channels = tuple((_ROOT_CHANNELS if p is None else _ROT_CHANNELS) if ch else ()
                     for _, p, _, ch in _JOINTS)
    return Skeleton(names=JOINT_NAMES, parents=parents, offsets=offsets, channels=channels)


# Column of each channelled joint's first channel in Motion.values (root: 6 columns, others 3).
_COL: dict[str, int] = {}
_c = 0
for _name, _p, _o, _ch in _JOINTS:
    if _ch:
        _COL[_name] = _c
        _c += 6 if _p is None else 3
NUM_CHANNELS = _c
del _c, _name, _p, _o, _ch

# ----------------------------------------------------------------------------------------------
# Gait parameters and styles
# ----------------------------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class GaitParams:
    """A walking style. Units in brackets; all continuous, so they can be probed from w."""

    stride_length: float  # [m] distance covered per gait cycle (two steps)
    cadence: float  # [steps/s]
    foot_lift: float  # [m] peak rise of the swing ankle above its stance height ("knee lift")
    crouch: float  # [deg] extra knee flexion at mid-stance (lowers the pelvis)
    torso_lean: float  # [deg] forward lean of the trunk (pelvis tilt + spine), forward +
    head_tilt: float  # [deg] neck + head flexion relative to the trunk, down +
    arm_swing: float  # [deg] shoulder flexion amplitude (half the forward-backward range)
    elbow_bend: float  # [deg] mean elbow flexion
    vertical_bounce: float  # [m] pelvis drop at double support below mid-stance height
    lateral_sway: float  # [m] pelvis sway amplitude toward the stance foot (also widens steps)

    @property
    def speed(self) -> float:
        """Walking speed [m/s] = stride_length * cadence / 2."""
        return self.stride_length * self.cadence / 2.0

    @property
    def stride_frequency(self) -> float:
        """Gait cycles per second [Hz] = cadence / 2."""
        return self.cadence / 2.0

    @property
    def step_width(self) -> float:
        """Lateral distance between the left and right foot paths [m]."""
        return 0.10 + 1.5 * self.lateral_sway

    @property
    def stance_fraction(self) -> float:
        """Fraction of the gait cycle a foot is on the ground (shorter when faster)."""
        return float(np.clip(0.68 - 0.05 * self.speed, 0.55, 0.68))

    def to_dict(self) -> dict[str, float]:
        return dataclasses.asdict(self)

    def jittered(self, rng: np.random.Generator, rel: float = 0.04) -> GaitParams:
        """Each field scaled by (1 + rel * n), n ~ N(0, 1) clipped to +-2."""
        names = [f.name for f in dataclasses.fields(self)]
        n = np.clip(rng.standard_normal(len(names)), -2.0, 2.0)
        return GaitParams(**{k: float(getattr(self, k) * (1.0 + rel * e)) for k, e in zip(names, n)})


PARAM_NAMES: tuple[str, ...] = tuple(f.name for f in dataclasses.fields(GaitParams))

STYLES: dict[str, GaitParams] = {
    "Normal": GaitParams(stride_length=1.40, cadence=1.85, foot_lift=0.10, crouch=0.0, torso_lean=3.0,
                         head_tilt=0.0, arm_swing=18.0, elbow_bend=15.0, vertical_bounce=0.045,
                         lateral_sway=0.025),
    "Marching": GaitParams(stride_length=1.50, cadence=2.00, foot_lift=0.30, crouch=0.0, torso_lean=-2.0,
                           head_tilt=-5.0, arm_swing=35.0, elbow_bend=5.0, vertical_bounce=0.05,
                           lateral_sway=0.02),
    "OldMan": GaitParams(stride_length=0.85, cadence=1.50, foot_lift=0.05, crouch=20.0, torso_lean=22.0,
                         head_tilt=-12.0, arm_swing=8.0, elbow_bend=30.0, vertical_bounce=0.02,
                         lateral_sway=0.035),
    "Sad": GaitParams(stride_length=1.00, cadence=1.45, foot_lift=0.06, crouch=5.0, torso_lean=10.0,
                      head_tilt=28.0, arm_swing=5.0, elbow_bend=8.0, vertical_bounce=0.02,
                      lateral_sway=0.02),
    "Happy": GaitParams(stride_length=1.50, cadence=2.20, foot_lift=0.14, crouch=0.0, torso_lean=-3.0,
                        head_tilt=-10.0, arm_swing=30.0, elbow_bend=45.0, vertical_bounce=0.08,
                        lateral_sway=0.03),
    "Sneaky": GaitParams(stride_length=0.90, cadence=1.20, foot_lift=0.16, crouch=40.0, torso_lean=15.0,
                         head_tilt=-8.0, arm_swing=6.0, elbow_bend=80.0, vertical_bounce=0.015,
                         lateral_sway=0.02),
    "Strong": GaitParams(stride_length=1.45, cadence=1.70, foot_lift=0.10, crouch=5.0, torso_lean=-4.0,
                         head_tilt=-5.0, arm_swing=22.0, elbow_bend=30.0, vertical_bounce=0.04,
                         lateral_sway=0.06),
    "Drunk": GaitParams(stride_length=1.10, cadence=1.60, foot_lift=0.06, crouch=8.0, torso_lean=8.0,
                        head_tilt=12.0, arm_swing=14.0, elbow_bend=20.0, vertical_bounce=0.03,
                        lateral_sway=0.10),
    "Childish": GaitParams(stride_length=1.00, cadence=2.50, foot_lift=0.12, crouch=5.0, torso_lean=0.0,
                           head_tilt=-5.0, arm_swing=35.0, elbow_bend=40.0, vertical_bounce=0.07,
                           lateral_sway=0.035),
}

# ----------------------------------------------------------------------------------------------
# Small rotation helpers (numpy, vectorised over frames)
# ----------------------------------------------------------------------------------------------


def _rx(a):
    c, s = np.cos(a), np.sin(a)
    o, z = np.ones_like(a), np.zeros_like(a)
    return np.stack([np.stack([o, z, z], -1), np.stack([z, c, -s], -1), np.stack([z, s, c], -1)], -2)


def _ry(a):
    c, s = np.cos(a), np.sin(a)
    o, z = np.ones_like(a), np.zeros_like(a)
    return np.stack([np.stack([c, z, s], -1), np.stack([z, o, z], -1), np.stack([-s, z, c], -1)], -2)


def _rz(a):
    c, s = np.cos(a), np.sin(a)
    o, z = np.ones_like(a), np.zeros_like(a)
    return np.stack([np.stack([c, -s, z], -1), np.stack([s, c, z], -1), np.stack([z, z, o], -1)], -2)


def _zyx_deg(mats: np.ndarray) -> np.ndarray:
    """Rotation matrices (N,3,3) -> (N,3) degrees (z, y, x) with R = Rz Ry Rx (BVH ZYX channels)."""
    return Rotation.from_matrix(mats).as_euler("ZYX", degrees=True)


def _smoothstep(x):
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def _min_jerk(x):
    x = np.clip(x, 0.0, 1.0)
    return x ** 3 * (10.0 - 15.0 * x + 6.0 * x * x)


def _mv(m, v):
    return np.einsum("...ij,...j->...i", m, v)


# ----------------------------------------------------------------------------------------------
# Seeds
# ----------------------------------------------------------------------------------------------


def _rng(key_or_seed) -> np.random.Generator:
    """numpy Generator from an int, a sequence of non-negative ints, a SeedSequence or a JAX key."""
    if isinstance(key_or_seed, np.random.SeedSequence):
        return np.random.default_rng(key_or_seed)
    if isinstance(key_or_seed, (int, np.integer)):
        entropy = [int(key_or_seed)]
    else:
        x = key_or_seed
        dtype = getattr(x, "dtype", None)
        if dtype is not None and type(x).__module__.startswith("jax"):
            import jax

            if jax.dtypes.issubdtype(dtype, jax.dtypes.prng_key):
                x = jax.random.key_data(x)
        entropy = [int(v) for v in np.asarray(x).ravel()]
    if any(v < 0 for v in entropy):
        raise ValueError(f"seeds must be non-negative integers, got {key_or_seed!r}")
    return np.random.default_rng(np.random.SeedSequence(entropy))


def clip_seed(seed: int, style: str, clip: int) -> np.random.SeedSequence:
    """The seed of clip `clip` (1-based) of `style` in a dataset made with `seed`. Independent
    of which other styles are generated."""
    return np.random.SeedSequence([int(seed), zlib.crc32(style.encode("utf-8")), int(clip)])


# ----------------------------------------------------------------------------------------------
# The walk
# ----------------------------------------------------------------------------------------------

_U = UNITS_TO_M
_L1 = _THIGH * _U
_L2 = _SHIN * _U
_ANKLE_H = -_TOE[1] * _U  # ankle height above the floor with the foot flat
_HIP_M = np.array(_HIP) * _U
_BALL_M = np.array(_TOE) * _U
_HEEL_M = np.array(_HEEL) * _U
_FOOT_UNDER_HIP = 0.35  # fraction of the stance at which the flat foot is under the hip joint
_SPINE_SHARE = {"pelvis": 0.35, "LowerBack": 0.45, "Spine": 0.15, "Spine1": 0.05}


def _leg_reach(knee_flex_deg: float) -> float:
    """Hip-to-ankle distance [m] with the knee flexed by knee_flex_deg."""
    k = np.deg2rad(knee_flex_deg)
    return float(np.sqrt(_L1 ** 2 + _L2 ** 2 + 2 * _L1 * _L2 * np.cos(k)))


def _path(rng: np.random.Generator, s: np.ndarray):
    """Random smooth floor path sampled at arc lengths s (increasing, metres, s[0] <= 0).

    Returns (x, z, heading) with heading = atan2(dx/ds, dz/ds) (0 = +Z) and (x, z) = 0 at s = 0.
    The shape as a function of s does not depend on the range of s (the sharp turns are two
    Poisson processes walking away from s = 0 with their own generators), and the number of
    draws from `rng` is fixed."""
    heading0 = rng.uniform(-np.pi, np.pi)
    kappa = np.zeros_like(s)
    for _ in range(3):  # gentle: wavelengths 8-30 m, |kappa| mostly < 0.2 1/m
        lam, amp, phase = rng.uniform(8.0, 30.0), rng.normal(0.0, 0.07), rng.uniform(0, 2 * np.pi)
        kappa += amp * np.sin(2 * np.pi * s / lam + phase)
    for direction in (1.0, -1.0):  # sharper turns: 45-120 degrees over ~1-2 m, one per ~12 m
        sub = np.random.default_rng(rng.integers(0, 2 ** 63))
        centre = 0.0
        while True:
            centre += direction * sub.exponential(12.0)
            if not s[0] - 3.0 <= centre <= s[-1] + 3.0:
                break
            width = sub.uniform(0.5, 1.0)
            angle = np.deg2rad(sub.uniform(45.0, 120.0)) * sub.choice([-1.0, 1.0])
            kappa += angle / (width * np.sqrt(2 * np.pi)) * np.exp(-0.5 * ((s - centre) / width) ** 2)
    ds = np.diff(s)
    i0 = int(np.argmin(np.abs(s)))  # s = 0 is on the grid
    heading = np.concatenate([[0.0], np.cumsum(0.5 * (kappa[1:] + kappa[:-1]) * ds)])
    heading = heading0 + heading - heading[i0]
    mid = 0.5 * (heading[1:] + heading[:-1])
    x = np.concatenate([[0.0], np.cumsum(np.sin(mid) * ds)])
    z = np.concatenate([[0.0], np.cumsum(np.cos(mid) * ds)])
    return x - x[i0], z - z[i0], heading


def _foot_pose(flat_ankle, psi, alpha, phi=None):
    """Ankle position of a stance foot whose flat-foot ankle position is `flat_ankle`, yaw psi,
    pitched by alpha (toes up +) about the heel (alpha > 0) or the ball (alpha < 0). phi <= 0: the toe
    segment itself pitched toes-down by -phi about the toe tip, lifting the ball (push-off)."""
    pivot = np.where((alpha > 0)[..., None], _HEEL_M, _BALL_M)
    if phi is not None:
        tip = np.array([0.0, 0.0, _TOE_END * _U])
        pivot = pivot + (alpha <= 0)[..., None] * (tip - _mv(_rx(-phi), tip))
    return flat_ankle + _mv(_ry(psi), pivot - _mv(_rx(-alpha), np.where((alpha > 0)[..., None], _HEEL_M, _BALL_M)))


def _two_link_ik(d):
    """Leg IK in the pelvis frame. d: (N,3) hip-joint -> ankle vector (m).

    Returns (abduction about Z, flexion (forward +), knee flexion), radians; the leg is
    R = Rz(abd) Rx(-flex) for the thigh and Rx(knee) for the shin."""
    dx, dy, dz = d[:, 0], d[:, 1], d[:, 2]
    r = np.sqrt(dx * dx + dy * dy)
    abd = np.arctan2(dx, -dy)
    dist = np.sqrt(r * r + dz * dz)
    dist = np.clip(dist, abs(_L1 - _L2) + 1e-3, _leg_reach(2.0))
    knee = np.pi - np.arccos(np.clip((_L1 ** 2 + _L2 ** 2 - dist ** 2) / (2 * _L1 * _L2), -1, 1))
    to_target = np.arctan2(dz, r)  # forward angle of the hip->ankle line from straight down
    inner = np.arccos(np.clip((_L1 ** 2 + dist ** 2 - _L2 ** 2) / (2 * _L1 * dist), -1, 1))
    return abd, to_target + inner, knee


def clip_params(params: GaitParams, key_or_seed, jitter: float = 0.04) -> GaitParams:
    """The jittered gait parameters that generate_clip(params, key_or_seed=..., jitter=...)
    actually walks with: the ground truth of that clip."""
    return params.jittered(_rng(key_or_seed), jitter)


def generate_clip(params: GaitParams, *, key_or_seed, num_frames: int, fps: float = 60.0,
                  jitter: float = 0.04, source: str = "<synthetic>") -> Motion:
    """One walk of `num_frames` frames (frame 0 a T-pose) at `fps`, deterministic in the seed.

    key_or_seed: int, sequence of non-negative ints, numpy SeedSequence or JAX PRNG key.
    jitter: relative per-clip variation of the gait parameters (0 disables it; the path and
    phase stay the same). The parameters actually used: clip_params(params, key_or_seed, jitter)."""
    if num_frames < 2:
        raise ValueError("num_frames must be >= 2 (frame 0 is the T-pose)")
    rng = _rng(key_or_seed)
    p = params.jittered(rng, jitter)  # always the first draw: see clip_params
    F = int(num_frames)
    t = np.arange(F) / fps
    v = p.speed
    f = p.stride_frequency
    beta = p.stance_fraction
    stride_ratio = p.stride_length / 1.4

    # Path on an extended time range so that footholds before/after the clip exist.
    pad = 2.0 / f + 1.0
    step = 0.5 / fps
    t_ext = np.arange(-int(np.ceil(pad / step)), int(np.ceil((t[-1] + pad) / step)) + 1) * step
    px, pz, ph = _path(rng, v * t_ext)

    def path_at(tt):
        return (np.interp(tt, t_ext, px), np.interp(tt, t_ext, pz), np.interp(tt, t_ext, ph))

    # Gait phase (cycles). Left heel strike at integer u, right at integer + 0.5.
    u0 = rng.uniform(0.0, 1.0)
    u = u0 + f * t
    x, z, heading = path_at(t)
    left = np.stack([np.cos(heading), np.zeros(F), -np.sin(heading)], -1)

    # Pelvis.
    uL = u
    twist = -np.deg2rad(4.0 * stride_ratio) * np.cos(2 * np.pi * uL)
    obliquity = np.deg2rad(3.0 + 40.0 * p.lateral_sway) * np.cos(2 * np.pi * (uL - beta / 2))
    tilt = np.full(F, np.deg2rad(_SPINE_SHARE["pelvis"] * p.torso_lean))
    sway = p.lateral_sway * np.cos(2 * np.pi * (uL - beta / 2 - 0.05))
    root_xz = np.stack([x, np.zeros(F), z], -1) + left * sway[:, None]
    R_pelvis = _ry(twist) @ _rz(obliquity) @ _rx(tilt)
    R_root = _ry(heading) @ R_pelvis

    # Feet: stance footholds in the world, swing trajectories between them.
    theta_hs = np.deg2rad(np.clip(15.0 * stride_ratio, 5.0, 22.0))
    theta_to = np.deg2rad(np.clip(50.0 * stride_ratio, 15.0, 60.0))
    p_heel = 0.10  # end of the heel rocker
    p_roll = 0.30 * beta / 0.62  # heel rises from here
    theta_tt = np.deg2rad(np.clip(30.0 * stride_ratio, 10.0, 35.0))
    p_toe = beta - 0.08  # the ball rises (pivot on the toe tip) from here
    toe_out = np.deg2rad(7.0)
    legs = {}
    for side, off, sign in (("L", 0.0, 1.0), ("R", 0.5, -1.0)):
        ul = u - off
        k = np.floor(ul).astype(int)
        ph_ = ul - k
        ks = np.arange(k.min() - 1, k.max() + 3)
        tk = (ks + _FOOT_UNDER_HIP * beta + off - u0) / f  # times when the ankle is under the hip joint
        kx, kz, kh = path_at(tk)
        k_left = np.stack([np.cos(kh), np.zeros_like(kh), -np.sin(kh)], -1)
        k_fwd = np.stack([np.sin(kh), np.zeros_like(kh), np.cos(kh)], -1)
        flat_ankle = (np.stack([kx, np.full_like(kx, _ANKLE_H), kz], -1) + k_left * (sign * p.step_width / 2)
                      + k_fwd * _HIP_M[2])
        psi = kh + sign * toe_out
        i = k - ks[0]
        stance = ph_ < beta
        # Stance.
        a_st = np.where(ph_ < p_heel, theta_hs * (1 - _smoothstep(ph_ / p_heel)),
                        -theta_to * np.clip((ph_ - p_roll) / (beta - p_roll), 0.0, 1.0) ** 2)
        phi_st = -theta_tt * np.clip((ph_ - p_toe) / (beta - p_toe), 0.0, 1.0) ** 2
        ank_st = _foot_pose(flat_ankle[i], psi[i], a_st, phi_st)
        # Swing from stance i (toe-off) to stance i + 1 (heel strike).
        sw = np.clip((ph_ - beta) / (1 - beta), 0.0, 1.0)
        P0 = _foot_pose(flat_ankle[i], psi[i], np.full(F, -theta_to), np.full(F, -theta_tt))
        P1 = _foot_pose(flat_ankle[np.minimum(i + 1, len(ks) - 1)], psi[np.minimum(i + 1, len(ks) - 1)],
                        np.full(F, theta_hs))
        m = _min_jerk(sw)
        ank_sw = P0 + (P1 - P0) * m[:, None]
        ank_sw[:, 1] += p.foot_lift * np.sin(np.pi * sw ** 0.8) ** 2
        a_sw = -theta_to + (theta_to + theta_hs) * _smoothstep(sw / 0.7)
        psi_sw = psi[i] + (np.unwrap(np.stack([psi[i], psi[np.minimum(i + 1, len(ks) - 1)]]), axis=0)[1]
                           - psi[i]) * m
        ankle = np.where(stance[:, None], ank_st, ank_sw)
        alpha = np.where(stance, a_st, a_sw)
        yaw = np.where(stance, psi[i], psi_sw)
        toe = np.where(stance, np.maximum(phi_st - a_st, 0.0),
                       (theta_to - theta_tt) * (1 - _smoothstep(sw / 0.35)))
        # Reach matters for the pelvis height only while the foot is (nearly) on the ground.
        relax = 0.5 * _smoothstep(sw / 0.3) * (1.0 - _smoothstep((sw - 0.5) / 0.3))
        legs[side] = (ankle, alpha, yaw, toe, sign, relax)

    # Pelvis height: crouch-dependent standing height, minus the bounce, capped by leg reach.
    stand = _ANKLE_H + _leg_reach(8.0 + p.crouch) - _HIP_M[1]
    shape = 0.5 * (1 - np.cos(4 * np.pi * (uL - beta / 2)))  # 1 at the double supports
    nominal = stand - p.vertical_bounce * shape
    caps = []
    reach = _leg_reach(6.0 + p.crouch)
    for side, (ankle, _, _, _, sign, relax) in legs.items():
        off = _mv(R_root, _HIP_M * np.array([sign, 1.0, 1.0]))
        hip_xz = root_xz + off * np.array([1.0, 0.0, 1.0])
        dh2 = np.sum((ankle - hip_xz) * np.array([1.0, 0.0, 1.0]) * (ankle - hip_xz), -1)
        caps.append(ankle[:, 1] + np.sqrt(np.maximum(reach ** 2 - dh2, 0.05 ** 2)) - off[:, 1] + relax)
    # The reach cap dips (V-shaped) at the double supports; the longer the stride, the deeper.
    # (a) Its smooth lower envelope; (b) the bounce curve lowered as a whole (over a window of
    # one gait cycle) until it fits under the cap, so that the pelvis excursion is the
    # vertical_bounce parameter also where the stride alone would make it larger. The pelvis
    # height is the soft minimum of (a), (b) and the nominal height.
    cap = np.min(caps, 0)
    width = max(3, int(round(0.08 * fps / f)))
    env = gaussian_filter1d(minimum_filter1d(cap, size=width, mode="nearest"), sigma=width / 3, mode="nearest")
    cycle = max(3, int(round(fps / f)))
    level = gaussian_filter1d(minimum_filter1d(cap + p.vertical_bounce * shape, size=cycle, mode="nearest"),
                              sigma=cycle / 4, mode="nearest")
    tau = 0.003
    both = np.stack([nominal, env, level - p.vertical_bounce * shape])
    low = both.min(0)
    root_y = low - tau * np.log(np.sum(np.exp(-(both - low) / tau), 0))
    root = root_xz + np.array([0.0, 1.0, 0.0]) * root_y[:, None]

    values = np.zeros((F, NUM_CHANNELS))

    def put(name, zyx_deg):
        c = _COL[name]
        values[:, c:c + 3] = zyx_deg

    values[:, 0:3] = root / _U
    values[:, 3:6] = _zyx_deg(R_root)

    # Legs.
    for side, (ankle, alpha, yaw, toe, sign, _) in legs.items():
        name = "Left" if side == "L" else "Right"
        hip = root + _mv(R_root, _HIP_M * np.array([sign, 1.0, 1.0]))
        d = _mv(np.swapaxes(R_root, -1, -2), ankle - hip)
        abd, flex, knee = _two_link_ik(d)
        put(f"{name}UpLeg", np.rad2deg(np.stack([abd, np.zeros(F), -flex], -1)))
        put(f"{name}Leg", np.rad2deg(np.stack([np.zeros(F), np.zeros(F), knee], -1)))
        R_shin = R_root @ _rz(abd) @ _rx(knee - flex)
        R_foot = _ry(yaw) @ _rx(-alpha)
        put(f"{name}Foot", _zyx_deg(np.swapaxes(R_shin, -1, -2) @ R_foot))
        put(f"{name}ToeBase", np.rad2deg(np.stack([np.zeros(F), np.zeros(F), -toe], -1)))

    # Spine and head: lean forward (X +), counter-rotate the thorax, undo the pelvic obliquity.
    lean = p.torso_lean
    for name in ("LowerBack", "Spine", "Spine1"):
        share = _SPINE_SHARE[name]
        put(name, np.stack([-np.rad2deg(obliquity) * (0.7 if name == "LowerBack" else 0.0),
                            -0.5 * np.rad2deg(twist), np.full(F, share * lean)], -1))
    bob = 2.0 * np.cos(4 * np.pi * (uL - beta / 2)) * p.vertical_bounce / 0.05
    head = 0.5 * p.head_tilt + 0.5 * bob  # split over Neck1 and Head
    put("Neck1", np.stack([np.zeros(F), 0.25 * np.rad2deg(twist), head], -1))
    put("Head", np.stack([np.zeros(F), 0.25 * np.rad2deg(twist), head], -1))

    # Arms: hang (about Z), swing (about the thorax X axis) in counter phase to the legs.
    abduct = 7.0 + 60.0 * p.lateral_sway
    lag = 0.05
    for name, off, sign in (("Left", 0.0, 1.0), ("Right", 0.5, -1.0)):
        ph_arm = 2 * np.pi * (u - off - lag)
        swing = 0.8 * lean + p.arm_swing * -np.cos(ph_arm)
        R_arm = _rx(np.deg2rad(-swing)) @ _rz(np.full(F, np.deg2rad(-sign * (90.0 - abduct))))
        put(f"{name}Arm", _zyx_deg(R_arm))
        elbow = p.elbow_bend + 0.3 * p.arm_swing * (0.5 - 0.5 * np.cos(ph_arm))
        put(f"{name}ForeArm", np.stack([np.zeros(F), -sign * elbow, np.zeros(F)], -1))
        put(f"{name}Hand", np.stack([np.full(F, -sign * 8.0), -sign * 0.3 * elbow, np.zeros(F)], -1))

    # Frame 0: T-pose, feet on the floor, at the walk's start position.
    values[0] = 0.0
    values[0, 0:3] = root[1] / _U if F > 1 else 0.0
    values[0, 1] = (_ANKLE_H - _HIP_M[1] + _L1 + _L2) / _U

    motion = Motion(skeleton=cmu_skeleton(), frame_time=1.0 / fps, values=values, source=source)
    return _put_on_floor(motion, fps)


def foot_heights(world_FxJx3: np.ndarray, *, units_to_m: float = 1.0) -> np.ndarray:
    """Height of the lowest point of each foot, (F, 2) [left, right], from world joint positions
    of this skeleton in file units times `units_to_m` (1.0: file units; UNITS_TO_M: metres).
    Points: the ball, the toe tip and the heel, estimated as the ankle minus the flat-foot ankle
    height."""
    ank = -_TOE[1] * units_to_m
    out = []
    for side in ("Left", "Right"):
        pts = np.stack([world_FxJx3[:, _IDX[f"{side}ToeBase"], 1],
                        world_FxJx3[:, _IDX[f"{side}ToeBase_EndSite"], 1],
                        world_FxJx3[:, _IDX[f"{side}Foot"], 1] - ank], -1)
        out.append(pts.min(-1))
    return np.stack(out, -1)


def _put_on_floor(motion: Motion, fps: float) -> Motion:
    from motiongan_jax.motion import kinematics

    world = np.asarray(kinematics.world_positions(motion), dtype=np.float64)
    c = foot_heights(world).min(-1)  # file units
    c_walk = c[1:]
    w = max(1, int(round(0.1 * fps)))
    c_walk = minimum_filter1d(c_walk, size=w, mode="nearest")
    c_walk = gaussian_filter1d(c_walk, sigma=max(0.5, 0.02 * fps), mode="nearest")
    c_walk = np.minimum(c_walk, c[1:])  # never push a foot below the floor by smoothing
    values = motion.values.copy()
    values[1:, 1] -= c_walk
    return dataclasses.replace(motion, values=values)


# ----------------------------------------------------------------------------------------------
# Dataset on disk
# ----------------------------------------------------------------------------------------------


def dataset_manifest(*, seed: int, clips_per_style: int, seconds: float, fps: float,
                     styles: Sequence[str]) -> dict:
    return {
        "generator": "motiongan_jax.synthetic",
        "version": VERSION,
        "seed": int(seed),
        "fps": float(fps),
        "seconds": float(seconds),
        "clips_per_style": int(clips_per_style),
        "units": UNITS,
        "units_to_m": UNITS_TO_M,
        "frame0": "T-pose (all rotations zero); drop with start_offset=1",
        "speed_formula": "speed [m/s] = stride_length * cadence / 2",
        "per_clip_jitter": "each parameter scaled by (1 + 0.04 n), n ~ N(0,1) clipped to +-2",
        "param_units": {"stride_length": "m per gait cycle (two steps)", "cadence": "steps/s",
                        "foot_lift": "m", "crouch": "deg", "torso_lean": "deg, forward +",
                        "head_tilt": "deg, down +, relative to the trunk", "arm_swing": "deg (amplitude)",
                        "elbow_bend": "deg", "vertical_bounce": "m", "lateral_sway": "m"},
        "styles": {s: STYLES[s].to_dict() for s in styles},
        "clips": {f"{s}_{n:02d}": clip_params(STYLES[s], clip_seed(seed, s, n)).to_dict()
                  for s in styles for n in range(1, clips_per_style + 1)},
    }


def write_dataset(out_dir: str | Path, *, seed: int = 0, clips_per_style: int = 5,
                  seconds: float = 16.0, fps: float = 60.0, styles: Sequence[str] | None = None,
                  overwrite: bool = False) -> Path:
    """Write `<Style>_<NN>.bvh` (NN = 01..clips_per_style) and styles.json into out_dir.

    Atomic: everything is written into a temporary directory beside out_dir, which is then
    renamed. If out_dir exists: FileExistsError, unless overwrite (then it is replaced).
    Each clip is `seconds` of walking plus the T-pose frame 0. Same arguments -> same bytes."""
    out = Path(out_dir)
    names = list(STYLES) if styles is None else list(styles)
    unknown = [s for s in names if s not in STYLES]
    if unknown:
        raise ValueError(f"unknown style(s) {unknown}; known: {list(STYLES)}")
    if clips_per_style < 1 or clips_per_style > 99:
        raise ValueError("clips_per_style must be in 1..99")
    if out.exists() and not overwrite:
        raise FileExistsError(f"{out} exists; pass overwrite=True to replace it")
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(dir=out.parent, prefix=f".{out.name}.tmp-"))
    try:
        num_frames = int(round(seconds * fps)) + 1
        for style in names:
            for n in range(1, clips_per_style + 1):
                fname = f"{style}_{n:02d}.bvh"
                motion = generate_clip(STYLES[style], key_or_seed=clip_seed(seed, style, n),
                                       num_frames=num_frames, fps=fps, source=fname)
                write_bvh(tmp / fname, motion, precision=4)
        manifest = dataset_manifest(seed=seed, clips_per_style=clips_per_style, seconds=seconds,
                                    fps=fps, styles=names)
        (tmp / "styles.json").write_text(json.dumps(manifest, indent=2, sort_keys=True) + "\n")
        if out.exists():  # overwrite: move the old one aside first
            old = Path(tempfile.mkdtemp(dir=out.parent, prefix=f".{out.name}.old-"))
            os.replace(out, old / out.name)
            os.rename(tmp, out)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.rename(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return out


def default_dataset_dir(seed: int = 0) -> Path:
    """$MOTIONGAN_CACHE (default ~/.cache/motiongan_jax)/synthetic-v{VERSION}-seed{seed}, generated
    with the default settings if missing. Safe when processes race: the loser uses the winner's."""
    out = cache_root() / f"synthetic-v{VERSION}-seed{int(seed)}"
    if (out / "styles.json").is_file():
        return out
    if out.exists():
        raise RuntimeError(f"{out} exists but has no styles.json (not made by this module?); delete it")
    try:
        write_dataset(out, seed=seed)
    except OSError:
        # Another process renamed its directory into place first (rename onto a non-empty
        # directory fails); use theirs.
        if not (out / "styles.json").is_file():
            raise
    return out
