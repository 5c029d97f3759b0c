"""PyTorch twins of our networks and training step, for bench/bench_vs_torch.py only.

Written from this package's own modules, layer for layer, so that the side-by-side bench times
the same network on both frameworks. PyTorch is the `bench` extra of pyproject.toml: nothing in
the package or the tests imports this file.

Layout is PyTorch's NCHW = (B, C, T, W) where ours is NHWC = (B, T, W, C); parameters keep the
names of ours (`ec0_0.conv.weight` is our `ec0_0.conv.kernel`), so `load_ours` copies an
initialised state across, converting layouts as nn/layers.py's docstring says.

* `Generator`: nn/generator.py in its straightforward form (tile, concatenate, bilinear x2
  upsampling, ConvTranspose2d), with `LatentTransform` (nn/latent.py) and AdaIN inside.
  `WalkerGenerator` adds the small presets' parts of nn/walker.py around it.
* `Discriminator`: nn/discriminator.py, `torch.nn.utils.spectral_norm` on every layer: the same
  power iteration as our `SpectralNorm` (v <- normalize(Mᵀu), then u <- normalize(Mv), σ = uᵀMv,
  one iteration per call in train mode, none flowing gradient), u and v as buffers; `projection`
  adds the projection head (model.d_cond).
* `TrainStep`: train/step.py: one G forward kept for backward, D updated on the detached fake
  and the real batch (D called fake then real), then G's losses through the updated D (one more D
  call) and one backward through that D into the stored G graph; Adam on both (β and learning
  rates of the config, eps 1e-8). D's parameters take no gradient during G's backward, as ours
  differentiate G's losses by the fake only. The losses are train/objectives.py's, each term
  ported from train/losses.py.

What differs from our step: ours also computes the global norms of gradients, parameters and
updates and the D accuracies every step (metrics; a few reductions over the parameters), which
this step computes only when asked (`measure=True`, the bench's check). Ours computes the same
functions with fewer FLOPs where nn/conv.py and nn/generator.py's "fast" form rewrites them
(docs/PERFORMANCE.md); this twin is the plain form, which is what PyTorch users would write.
"""

from __future__ import annotations

import math

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn
from torch.nn.utils import spectral_norm

from motiongan_jax.nn.discriminator import PADDED_ROWS
from motiongan_jax.nn.layers import LEAKY_SLOPE, NORM_EPS
from motiongan_jax.nn.walker import (
    PHASE_CHANNELS,
    PHASE_HARMONICS,
    STRIDE_GAIN,
    STRIDE_MIN_STEP_M,
    STRIDE_STEP_CENTRE_M,
)
from motiongan_jax.train.losses import CONTACT_SOFTNESS_M, FAKE_TARGET, REAL_TARGET, STEP_HEIGHT_FLOOR_M
from motiongan_jax.train.objectives import G_TERMS, PAPER_G_TERMS, g_weights


def leaky_relu(x):
    return F.leaky_relu(x, LEAKY_SLOPE)


def upsample_time2(x_BxCxTxW):
    """Linear x2 in time, PyTorch bilinear (2, 1) without corner alignment (layers.upsample_time2)."""
    return F.interpolate(x_BxCxTxW, scale_factor=(2, 1), mode="bilinear", align_corners=False)


# ---------------------------------------------------------------------------------------------
# Layers


class Conv(nn.Conv2d):
    """Reflect padding, kt//2 frames in time and `pad_w` rows in width, then a VALID convolution
    (layers.Conv)."""

    def __init__(self, cin: int, cout: int, kt: int, kw: int, stride=(1, 1), pad_w: int = 0):
        super().__init__(cin, cout, (kt, kw), stride)
        self.pads = (pad_w, pad_w, kt // 2, kt // 2)

    def forward(self, x):
        return super().forward(F.pad(x, self.pads, mode="reflect"))


class ConvTranspose(nn.ConvTranspose2d):
    """kt x 3 kernel, stride (1, 3), kt//2 frames cropped from each end of time (layers.ConvTranspose)."""

    def __init__(self, cin: int, cout: int, kt: int):
        super().__init__(cin, cout, (kt, 3), stride=(1, 3), padding=(kt // 2, 0))


class AdaIN(nn.Module):
    """instance_norm(h) · (A_s w + a_s) + (A_b w + a_b) (layers.AdaIN)."""

    def __init__(self, channels: int, w_dim: int):
        super().__init__()
        self.scale = nn.Linear(w_dim, channels)
        self.shift = nn.Linear(w_dim, channels)

    def forward(self, h, w):
        s, b = self.scale(w), self.shift(w)
        return F.instance_norm(h, eps=NORM_EPS) * s[:, :, None, None] + b[:, :, None, None]


class StyledBlock(nn.Module):
    """conv (or tconv) -> LeakyReLU -> AdaIN(w) (generator.StyledBlock)."""

    def __init__(self, conv: nn.Module, channels: int, w_dim: int):
        super().__init__()
        self.conv = conv
        self.adain = AdaIN(channels, w_dim)

    def forward(self, x, w):
        return self.adain(leaky_relu(self.conv(x)), w)


class LatentTransform(nn.Module):
    """w = MLP5(PixelNorm([z, E[label]])), LeakyReLU after every layer (nn/latent.py)."""

    def __init__(self, num_styles: int, z_dim: int, w_dim: int, num_layers: int = 5):
        super().__init__()
        self.embed = nn.Parameter(torch.randn(num_styles, z_dim))
        dims = [2 * z_dim] + [w_dim] * num_layers
        self.layers = nn.ModuleList(nn.Linear(dims[i], dims[i + 1]) for i in range(num_layers))

    def forward(self, labels_B, z_BxZ):
        h = torch.cat([z_BxZ, self.embed[labels_B]], -1)
        h = h * torch.rsqrt(h.square().mean(-1, keepdim=True) + NORM_EPS)
        for layer in self.layers:
            h = leaky_relu(layer(h))
        return h


# ---------------------------------------------------------------------------------------------
# G


class Generator(nn.Module):
    """The paper's G (nn/generator.py's table), Latent Transform included."""

    BLOCKS = ("ec0_0", "ec1_0", "ec1_1", "ec2_0", "ec2_1", "ec3_0", "ec3_1",
              "dc_bottom", "dc3_1", "dc3_0", "dc2_1", "dc2_0", "dc1_1", "dc1_0")

    def __init__(self, num_rel_joints: int = 27, *, base_channels: int = 64, time_kernel: int = 5,
                 w_dim: int = 64, z_dim: int = 64, num_styles: int, side_channels: int = 0,
                 length_unit: float = 1.0):
        super().__init__()
        kt = time_kernel
        self.num_rel_joints = num_rel_joints
        self.num_rows = 3 * num_rel_joints
        self.length_unit = float(length_unit)
        self.side_channels = side_channels
        self.latent = LatentTransform(num_styles, z_dim, w_dim)

        def conv(cin, cout, kw=1, stride=(1, 1), pad_w=0):
            return StyledBlock(Conv(cin, cout, kt, kw, stride, pad_w), cout, w_dim)

        def tconv(cin, cout):
            return StyledBlock(ConvTranspose(cin, cout, kt), cout, w_dim)

        c, s = base_channels, side_channels
        t1, t2, t4, t8 = c, 2 * c, 4 * c, 8 * c
        self.ec0_0 = conv(1 + s, t1)
        self.ec1_0 = conv(t1, t2, 3, (2, 3))
        self.ec1_1 = conv(t2, t2)
        self.ec2_0 = conv(t2, t4, 1, (2, 1))
        self.ec2_1 = conv(t4, t4)
        self.ec3_0 = conv(t4, t8, 1, (2, 1))
        self.ec3_1 = conv(t8, t8)
        self.dc_bottom = tconv(t8, t8)
        self.dc3_1 = tconv(t8, t8)
        self.dc3_0 = conv(t8, t4, 3, pad_w=1)
        self.dc2_1 = tconv(t4 + s + t4, t4)
        self.dc2_0 = conv(t4, t2, 3, pad_w=1)
        self.dc1_1 = tconv(t2 + s + t2, t2)
        self.dc1_0 = conv(t2 + s, t1, 3, pad_w=1)
        self.c_traj = Conv(t1, 3, kt, self.num_rows)
        self.dc0_0 = Conv(t1, 1, kt, 1)

    def style(self, labels_B, z_BxZ):
        return self.latent(labels_B, z_BxZ)

    def forward(self, curve_vel_BxTx3, w_BxD):
        return self.network((curve_vel_BxTx3 / self.length_unit)[:, None], w_BxD)

    def network(self, x_BxCxTx3, w, side_BxSxTx1=None):
        """(root_vel_BxTx3, pose_BxTxR) in metres for an input in the layers' unit."""

        def up(name, d, e=None):
            x = d if e is None else torch.cat([e.expand(-1, -1, -1, d.shape[3]), d], 1)
            return getattr(self, name)(upsample_time2(x), w)

        def with_side(e, rate):
            if side_BxSxTx1 is None:
                return e
            return torch.cat([e, side_BxSxTx1[:, :, ::rate].expand(-1, -1, -1, e.shape[3])], 1)

        x = self.ec0_0(x_BxCxTx3, w)
        x = self.ec1_0(x, w)
        e1 = self.ec1_1(x, w)
        x = self.ec2_0(e1, w)
        e2 = self.ec2_1(x, w)
        x = self.ec3_0(e2, w)
        x = self.ec3_1(x, w)
        x = up("dc3_1", self.dc_bottom(x, w))
        d2 = self.dc3_0(x, w)
        x = up("dc2_1", d2, with_side(e2, 4))
        d1 = self.dc2_0(x, w)[:, :, :, : self.num_rel_joints]
        x = up("dc1_1", d1, with_side(e1, 2))
        d0 = self.dc1_0(with_side(x, 1), w)
        root_vel_BxTx3 = self.c_traj(d0)[:, :, :, 0].transpose(1, 2) * self.length_unit
        pose_BxTxR = self.dc0_0(d0)[:, 0] * self.length_unit
        return root_vel_BxTx3, pose_BxTxR


# trajectory.py's helpers the walker needs (time is axis 1, xyz the last)


def velocity(x_BxTxD):
    d = x_BxTxD[:, 1:] - x_BxTxD[:, :-1]
    return torch.cat([d[:, 1:2], d], 1)


def integrate(start_BxD, v_BxTxD):
    steps = torch.cumsum(v_BxTxD[:, 1:], 1)
    return start_BxD[:, None] + torch.cat([torch.zeros_like(v_BxTxD[:, :1]), steps], 1)


def rotate_y(x_xx3, theta):
    c, s = torch.cos(theta), torch.sin(theta)
    px, pz = x_xx3[..., 0], x_xx3[..., 2]
    return torch.stack([c * px + s * pz, x_xx3[..., 1], -s * px + c * pz], -1)


def rotate_rows_y(pose_BxTxR, theta_BxT):
    b, t, r = pose_BxTxR.shape
    return rotate_y(pose_BxTxR.reshape(b, t, r // 3, 3), theta_BxT[..., None]).reshape(b, t, r)


def heading(v_BxTx3):
    return torch.atan2(v_BxTx3[..., 0], v_BxTx3[..., 2])


def smooth_heading(v_BxTx3, taps=(1.0, 4.0, 6.0, 4.0, 1.0)):
    xz = torch.stack([v_BxTx3[..., 0], v_BxTx3[..., 2]], -1)
    unit = xz / xz.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    k = torch.tensor(taps, dtype=v_BxTx3.dtype) / sum(taps)
    r, t = len(taps) // 2, unit.shape[1]
    idx = (torch.arange(t)[:, None] + torch.arange(-r, r + 1)[None, :]).clamp(0, t - 1)
    avg = torch.einsum("btkc,k->btc", unit[:, idx], k)
    return torch.atan2(avg[..., 0], avg[..., 1])


def walked_step(curve_vel_BxTx3):
    step = curve_vel_BxTx3[..., ::2].norm(dim=-1)
    return torch.cat([torch.zeros_like(step[:, :1]), step[:, 1:]], 1)


def project_bones(pose_BxTxR, bones):
    b, t, r = pose_BxTxR.shape
    raw = torch.cat([pose_BxTxR.new_zeros(b, t, 1, 3), pose_BxTxR.reshape(b, t, r // 3, 3)], 2)
    out = [raw[:, :, 0]] + [None] * (r // 3)
    for parent, child, length in sorted(bones, key=lambda x: x[1]):
        d = raw[:, :, child] - raw[:, :, parent]
        out[child] = out[parent] + (length / torch.sqrt(d.square().sum(-1, keepdim=True) + 1e-12)) * d
    return torch.stack(out[1:], 2).reshape(b, t, r)


class WalkerGenerator(Generator):
    """The paper's G with nn/walker.py's parts around it (config.WalkerConfig's options)."""

    def __init__(self, num_rel_joints: int, walker, *, rest_pose_R=None, bones=None, **paper):
        super().__init__(num_rel_joints, side_channels=PHASE_CHANNELS if walker.gait_phase else 0, **paper)
        self.walker = walker
        self.register_buffer("rest_pose_R", None if rest_pose_R is None else torch.tensor(rest_pose_R))
        self.bones = bones
        w_dim = self.latent.layers[-1].out_features
        self.stride_head = nn.Linear(w_dim, 2 if walker.stride_speed else 1) if walker.gait_phase else None

    def log_stride(self, w_BxD, curve_vel_BxTx3):
        head_BxK = STRIDE_GAIN * self.stride_head(w_BxD)
        if not self.walker.stride_speed:
            return head_BxK[:, 0]
        log_step_BxT = torch.log(walked_step(curve_vel_BxTx3).clamp_min(STRIDE_MIN_STEP_M) / STRIDE_STEP_CENTRE_M)
        return head_BxK[:, :1] + head_BxK[:, 1:2] * log_step_BxT

    def walked_phase(self, curve_vel_BxTx3, w_BxD, offset_B):
        stride = torch.exp(self.log_stride(w_BxD, curve_vel_BxTx3)).detach()
        step_BxT = walked_step(curve_vel_BxTx3)
        if stride.ndim == 1:
            return offset_B[:, None] + 2 * math.pi * torch.cumsum(step_BxT, 1) / stride[:, None]
        return offset_B[:, None] + 2 * math.pi * torch.cumsum(step_BxT / stride, 1)

    def forward(self, curve_vel_BxTx3, w_BxD, phase_offset_B=None, phase_BxT=None):
        b, t = curve_vel_BxTx3.shape[:2]
        vel_in = curve_vel_BxTx3
        if self.walker.frame == "curve":
            theta_BxT = heading(curve_vel_BxTx3)
            vel_in = rotate_y(curve_vel_BxTx3, -torch.cat([theta_BxT[:, :1], theta_BxT[:, :-1]], 1))
        x = (vel_in / self.length_unit)[:, None]  # B x 1 x T x 3
        side = None
        if self.walker.gait_phase:
            if phase_BxT is None:
                offset = curve_vel_BxTx3.new_zeros(b) if phase_offset_B is None else phase_offset_B
                phase_BxT = self.walked_phase(curve_vel_BxTx3, w_BxD, offset)
            a_BxTxH = phase_BxT[..., None] * torch.arange(1, PHASE_HARMONICS + 1, dtype=x.dtype)
            side = torch.cat([torch.sin(a_BxTxH), torch.cos(a_BxTxH)], -1).permute(0, 2, 1)[..., None]
            x = torch.cat([x, side.expand(-1, -1, -1, 3)], 1)
        root_vel, pose = self.network(x, w_BxD, side)
        if self.walker.root_height:
            dh = root_vel[..., 1][:, 1:] - root_vel[..., 1][:, :-1]
            root_vel = torch.stack([root_vel[..., 0], torch.cat([dh[:, :1], dh], 1), root_vel[..., 2]], -1)
        if self.rest_pose_R is not None:
            pose = pose + self.rest_pose_R
        if self.bones is not None:
            pose = project_bones(pose, self.bones)
        if self.walker.frame == "curve":
            out_BxT = smooth_heading(curve_vel_BxTx3)
            root_vel = rotate_y(root_vel, out_BxT)
            pose = rotate_rows_y(pose, out_BxT)
        if self.walker.output_prior:
            root_vel = root_vel + curve_vel_BxTx3
        return root_vel, pose


# ---------------------------------------------------------------------------------------------
# D


class Discriminator(nn.Module):
    """The paper's D (nn/discriminator.py's table), spectral norm on every layer; `projection`:
    the projection head of model.d_cond."""

    def __init__(self, num_rel_joints: int = 27, *, num_styles: int, seq_len: int = 128, base_channels: int = 64,
                 time_kernel: int = 5, length_unit: float = 1.0, projection: bool = False):
        super().__init__()
        kt, c = time_kernel, base_channels
        self.num_rel_joints = num_rel_joints
        self.length_unit = float(length_unit)
        self.c0_0 = spectral_norm(Conv(2, c, kt, 3, (2, 3)))
        self.c1_0 = spectral_norm(Conv(c, 2 * c, kt, 3, (2, 3)))
        self.c2_0 = spectral_norm(Conv(2 * c, 4 * c, kt, 3, (2, 3)))
        self.c3_0 = spectral_norm(Conv(4 * c, 8 * c, kt, 3, (2, 3)))
        feat = 8 * c * (seq_len // 16)
        self.l_last = spectral_norm(nn.Linear(feat, 1))
        self.l_cls = spectral_norm(nn.Linear(feat, num_styles))
        self.l_proj = spectral_norm(nn.Linear(feat, num_styles)) if projection else None

    def forward(self, root_vel_BxTx3, pose_BxTxR, labels_B=None):
        r = pose_BxTxR.shape[2]
        x = torch.stack([root_vel_BxTx3.repeat(1, 1, self.num_rel_joints), pose_BxTxR], 1) / self.length_unit
        x = F.pad(x, (0, PADDED_ROWS - r))  # B x 2 x T x 81
        for conv in (self.c0_0, self.c1_0, self.c2_0, self.c3_0):
            x = leaky_relu(conv(x))
        flat = x.flatten(1)  # channel-major: c·T/16 + t
        adv_B, cls_BxC = self.l_last(flat)[:, 0], self.l_cls(flat)
        if self.l_proj is not None:
            adv_B = adv_B + self.l_proj(flat).gather(1, labels_B[:, None])[:, 0]
        return adv_B, cls_BxC


# ---------------------------------------------------------------------------------------------
# Built from our config, loaded from our state


def build(cfg, layout, num_styles: int):
    """(G, D) of a config's model section, as model/build.py builds ours (parameters: `load_ours`)."""
    from motiongan_jax.model import build as ours
    from motiongan_jax.motion.representation import LENGTH_UNIT_M

    m, j = cfg.model, ours.count_rel_joints(layout)
    paper = dict(base_channels=m.base_channels, time_kernel=m.time_kernel, w_dim=m.w_dim, z_dim=m.z_dim,
                 num_styles=num_styles, length_unit=LENGTH_UNIT_M)
    if m.walker is None:
        g = Generator(j, **paper)
    else:
        g = WalkerGenerator(j, m.walker, rest_pose_R=ours.output_prior_rows(m, layout),
                            bones=ours.generator_bones(m, layout), **paper)
    d = Discriminator(j, num_styles=num_styles, seq_len=cfg.data.window_T, base_channels=m.base_channels,
                      time_kernel=m.time_kernel, length_unit=LENGTH_UNIT_M, projection=m.d_cond)
    return g, d


def _torch_value(module: nn.Module, name: str, value: np.ndarray) -> tuple[str, np.ndarray]:
    """Our (dotted name, array) -> the torch tensor's name and the array in its layout."""
    prefix, _, leaf = name.rpartition(".")
    if leaf in ("u", "v") and prefix.endswith(".sn"):
        return f"{prefix[:-3]}.weight_{leaf}", value
    if leaf == "embed":
        return name, value
    owner = module.get_submodule(prefix)
    if leaf == "bias":
        return name, value
    assert leaf == "kernel", name
    torch_leaf = "weight_orig" if hasattr(owner, "weight_orig") else "weight"
    if isinstance(owner, nn.ConvTranspose2d):
        value = value.transpose(2, 3, 0, 1)  # (kt, kw, in, out) -> (in, out, kt, kw)
    elif isinstance(owner, nn.Conv2d):
        value = value.transpose(3, 2, 0, 1)  # (kt, kw, in, out) -> (out, in, kt, kw)
    else:
        value = value.T  # (in, out) -> (out, in)
    return f"{prefix}.{torch_leaf}", value


def load_ours(module: nn.Module, *states) -> None:
    """Copy our nnx.State(s) (parameters, spectral-norm vectors) into `module`; every torch
    parameter and spectral-norm buffer must be written exactly once."""
    from flax import nnx

    targets = dict(module.named_parameters()) | {n: b for n, b in module.named_buffers() if n.endswith(("_u", "_v"))}
    written = set()
    for state in states:
        for path, var in nnx.to_flat_state(state):
            name, value = _torch_value(module, ".".join(str(p) for p in path), np.asarray(var[...]))
            target = targets[name]
            assert tuple(target.shape) == value.shape, (name, target.shape, value.shape)
            with torch.no_grad():
                target.copy_(torch.from_numpy(np.array(value, np.float32)))
            assert name not in written, name
            written.add(name)
    missing = sorted(set(targets) - written)
    assert not missing, f"not loaded: {missing}"


def count_params(module: nn.Module) -> int:
    return sum(p.numel() for p in module.parameters())


# ---------------------------------------------------------------------------------------------
# Losses (train/losses.py)


def adversarial_loss(logits_B, target: float, mode: str):
    t = torch.full_like(logits_B, target)
    if mode == "bce_prob":  # BCELoss on probabilities: logs clamped at -100, as ours copies
        return F.binary_cross_entropy(torch.sigmoid(logits_B), t)
    return F.binary_cross_entropy_with_logits(logits_B, t)


def class_loss(logits_BxC, labels_B, mode: str):
    if mode == "bce_prob":
        onehot = F.one_hot(labels_B, logits_BxC.shape[-1]).to(logits_BxC.dtype)
        return F.binary_cross_entropy(torch.softmax(logits_BxC, -1), onehot)
    return F.cross_entropy(logits_BxC, labels_B)


def curve_loss(root_vel_BxTx3, curve_BxTx3, points: int, unit: float):
    s = curve_BxTx3.shape[1] // points
    idx = torch.arange(1, points + 1) * s - 1
    diff = (integrate(curve_BxTx3[:, 0], root_vel_BxTx3)[:, idx] - curve_BxTx3[:, idx]) / unit
    return (0.5 * diff[..., [0, 2]].square().mean(0).sum(-1)).sum()


def joints_of(pose_BxTxR):
    b, t, r = pose_BxTxR.shape
    return torch.cat([pose_BxTxR.new_zeros(b, t, 1, 3), pose_BxTxR.reshape(b, t, r // 3, 3)], 2)


def bone_loss(pose_BxTxR, pairs_Px2, lengths_P, unit: float):
    joints = joints_of(pose_BxTxR)
    sq = (joints[:, :, pairs_Px2[:, 0]] - joints[:, :, pairs_Px2[:, 1]]).square().sum(-1)
    lengths = torch.where(sq > 0, torch.sqrt(torch.where(sq > 0, sq, torch.ones_like(sq))), torch.zeros_like(sq))
    return ((lengths - lengths_P) / unit).square().mean()


def world_joints(root_vel_BxTx3, pose_BxTxR):
    root = integrate(root_vel_BxTx3.new_zeros(root_vel_BxTx3.shape[0], 3), root_vel_BxTx3)
    return root[:, :, None] + joints_of(pose_BxTxR)


def foot_losses(root_vel_BxTx3, pose_BxTxR, toe_joints, contact_height_m: float, unit: float):
    toes = world_joints(root_vel_BxTx3, pose_BxTxR)[:, :, list(toe_joints)]
    h = toes[..., 1]
    h = h - h.amin(dim=(1, 2), keepdim=True)
    lift = h.amin(2) / unit
    step = toes[..., ::2].diff(dim=1).square().sum(-1) / unit**2
    contact = torch.sigmoid((contact_height_m - h[:, 1:]) / CONTACT_SOFTNESS_M)
    return lift.square().mean(), (contact * step).mean()


def step_height_loss(root_vel_BxTx3, pose_BxTxR, labels_B, toe_joints, step_height_m_C):
    heights = world_joints(root_vel_BxTx3, pose_BxTxR)[:, :, list(toe_joints), 1]
    diff = heights[..., 0] - heights[..., 1]
    var = (diff - diff.mean(1, keepdim=True)).square().mean(1)
    target = torch.log(torch.tensor(step_height_m_C, dtype=torch.float32))[labels_B]
    return (0.5 * torch.log(var + STEP_HEIGHT_FLOOR_M**2) - target).square().mean()


def root_jerk_excess(fake_vel, real_vel, unit: float):
    def mean_sq(v):
        return v.diff(n=2, dim=1).square().sum(-1).mean()
    return F.relu(mean_sq(fake_vel) - mean_sq(real_vel).detach()) / unit**2


def joint_jerk_excess(fake_vel, fake_pose, real_vel, real_pose, unit: float):
    def per_joint(v, p):
        return world_joints(v, p).diff(n=3, dim=1).square().sum(-1).mean((0, 1))
    return F.relu(per_joint(fake_vel, fake_pose) - per_joint(real_vel, real_pose).detach()).sum() / unit**2


def stride_loss(log_stride, labels_B, gait, step_m_BxT):
    log_stride_C = torch.log(torch.tensor(gait.stride_m_C, dtype=torch.float32))
    if log_stride.ndim == 1:
        return (log_stride - log_stride_C[labels_B]).square().mean()
    log_speed = torch.log((step_m_BxT[:, 1:] * gait.sample_hz).clamp_min(1e-6))
    log_speed_C = torch.log(torch.tensor(gait.speed_mps_C, dtype=torch.float32))
    target = log_stride_C[labels_B][:, None] + gait.stride_speed_slope * (log_speed - log_speed_C[labels_B][:, None])
    return (log_stride[:, 1:] - target).square().mean()


def reconstruction_loss(fake_vel, fake_pose, real_vel, real_pose, valid_BxT, unit: float):
    diff = (fake_vel - real_vel).abs().sum(-1) + (fake_pose - real_pose).abs().sum(-1)
    diff = diff / (unit * (3 + real_pose.shape[-1]))
    w = valid_BxT.to(diff.dtype)
    return (w * diff).sum() / w.sum().clamp_min(1.0)


# ---------------------------------------------------------------------------------------------
# The training step (train/step.py)


def _norm(tensors) -> float:
    return float(torch.sqrt(sum(t.double().square().sum() for t in tensors)))


class TrainStep:
    """One iteration of train/step.py on (G, D) built by `build`: `step(batch)` with the batch's
    tensors (root_BxTx3, pose_BxTxR, curve_BxTx3, label_B; phase_BxT, phase_valid_BxT, rec_B
    under train.w_g_rec). `draws` (labels, z, phase offsets or None) replaces the step's own
    random draws (the check gives ours); `measure` returns the loss terms and gradient norms."""

    def __init__(self, cfg, layout, num_styles: int, g: Generator, d: Discriminator, gait=None):
        from motiongan_jax.motion.representation import LENGTH_UNIT_M

        t = cfg.train
        self.cfg, self.t, self.g, self.d, self.gait = cfg, t, g, d, gait
        self.num_styles, self.unit = num_styles, LENGTH_UNIT_M
        self.weights = g_weights(t)
        self.active = [n for n in G_TERMS if n in PAPER_G_TERMS or self.weights[n]]
        self.pairs = torch.tensor(np.asarray(layout.bone_pairs, np.int64).reshape(-1, 2))
        self.lengths = torch.tensor(np.asarray(layout.bone_lengths_m, np.float32))
        self.opt_g = torch.optim.Adam(g.parameters(), lr=t.lr_g, betas=(t.beta1, t.beta2), eps=1e-8)
        self.opt_d = torch.optim.Adam(d.parameters(), lr=t.lr_d, betas=(t.beta1, t.beta2), eps=1e-8)
        self.ema = [p.detach().clone() for p in g.parameters()] if t.g_ema_decay > 0 else None
        g.train()
        d.train()  # a power iteration on every D call, as ours with update_stats=True

    def draws(self, batch):
        """(labels_B, z_BxZ, phase_offset_B or None): objectives.generator_inputs."""
        b = batch["curve_BxTx3"].shape[0]
        labels = torch.randint(0, self.num_styles, (b,))
        z = torch.randn(b, self.cfg.model.z_dim)
        phase = torch.rand(b) * (2 * math.pi) if self.cfg.model.gait_phase else None
        if self.t.w_g_rec:
            rec = batch["rec_B"]
            labels = torch.where(rec, batch["label_B"], labels)
            if self.t.rec_z == "zero":
                z = torch.where(rec[:, None], torch.zeros_like(z), z)
        return labels, z, phase

    def __call__(self, batch, draws=None, measure: bool = False):
        t, g, d, mode = self.t, self.g, self.d, self.t.gan_loss
        labels, z, phase = self.draws(batch) if draws is None else draws
        curve_vel, real_vel = velocity(batch["curve_BxTx3"]), velocity(batch["root_BxTx3"])
        real_pose = batch["pose_BxTxR"]

        # the single G forward, kept for G's backward
        w = g.style(labels, z)
        log_stride = None
        if isinstance(g, WalkerGenerator):
            phase_BxT = None
            if t.w_g_rec:
                offset = phase if phase is not None else curve_vel.new_zeros(len(labels))
                phase_BxT = torch.where(batch["rec_B"][:, None], batch["phase_BxT"],
                                        g.walked_phase(curve_vel, w, offset))
            fake_vel, fake_pose = g(curve_vel, w, phase, phase_BxT)
            log_stride = g.log_stride(w, curve_vel) if g.walker.gait_phase else None
        else:
            fake_vel, fake_pose = g(curve_vel, w)

        # D update on the detached fake and the real batch
        adv_f, _ = d(fake_vel.detach(), fake_pose.detach(), labels)
        adv_r, cls_r = d(real_vel, real_pose, batch["label_B"])
        d_adv_fake, d_adv_real = adversarial_loss(adv_f, FAKE_TARGET, mode), adversarial_loss(adv_r, REAL_TARGET, mode)
        d_adv = d_adv_fake + d_adv_real
        d_cls = class_loss(cls_r, batch["label_B"], mode)
        d_total = t.w_d_adv * d_adv + t.w_d_cls * d_cls
        self.opt_d.zero_grad(set_to_none=True)
        d_total.backward()
        d_grad_norm = _norm(p.grad for p in d.parameters()) if measure else None
        self.opt_d.step()

        # G update through the updated D (no gradient for D's parameters)
        d.requires_grad_(False)
        adv_f, cls_f = d(fake_vel, fake_pose, labels)
        terms = self._g_terms(adv_f, cls_f, fake_vel, fake_pose, labels, batch, real_vel, curve_vel, log_stride)
        g_total = sum(self.weights[n] * terms[n] for n in self.active)
        self.opt_g.zero_grad(set_to_none=True)
        g_total.backward()
        d.requires_grad_(True)
        g_grad_norm = _norm(p.grad for p in g.parameters()) if measure else None
        self.opt_g.step()
        if self.ema is not None:
            with torch.no_grad():
                params = list(g.parameters())
                torch._foreach_mul_(self.ema, t.g_ema_decay)
                torch._foreach_add_(self.ema, params, alpha=1 - t.g_ema_decay)
        if not measure:
            return None
        d_terms = {"d_adv_fake": d_adv_fake, "d_adv_real": d_adv_real, "d_adv": d_adv, "d_cls": d_cls,
                   "d_total": d_total}
        return {**{k: v.item() for k, v in d_terms.items()}, **{f"g_{n}": terms[n].item() for n in self.active},
                "g_total": g_total.item(), "d_grad_norm": d_grad_norm, "g_grad_norm": g_grad_norm}

    def _g_terms(self, adv_f, cls_f, fake_vel, fake_pose, labels, batch, real_vel, curve_vel, log_stride):
        t, unit, gait, mode = self.t, self.unit, self.gait, self.t.gan_loss
        terms = {"adv": adversarial_loss(adv_f, REAL_TARGET, mode), "cls": class_loss(cls_f, labels, mode),
                 "curve": curve_loss(fake_vel, batch["curve_BxTx3"], t.curve_points, unit),
                 "bone": bone_loss(fake_pose, self.pairs, self.lengths, unit)}
        active = self.active
        if "floor" in active or "skate" in active:
            terms["floor"], terms["skate"] = foot_losses(fake_vel, fake_pose, gait.toe_joints, gait.contact_height_m,
                                                         unit)
        if "step_height" in active:
            terms["step_height"] = step_height_loss(fake_vel, fake_pose, labels, gait.toe_joints,
                                                    gait.step_height_m_C)
        if "root_jerk" in active:
            terms["root_jerk"] = root_jerk_excess(fake_vel, real_vel, unit)
        if "joint_jerk" in active:
            terms["joint_jerk"] = joint_jerk_excess(fake_vel, fake_pose, real_vel, batch["pose_BxTxR"], unit)
        if "stride" in active:
            terms["stride"] = stride_loss(log_stride, labels, gait, walked_step(curve_vel))
        if "rec" in active:
            valid = batch["phase_valid_BxT"] & batch["rec_B"][:, None]
            terms["rec"] = reconstruction_loss(fake_vel, fake_pose, real_vel, batch["pose_BxTxR"], valid, unit)
        return terms
