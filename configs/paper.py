"""Exactly the paper: CMU styled walks (subjects 137 and 142), 28 styles, B 24, T 128, 200k steps.

The CMU trials are not shipped: download them and pass --data DIR (files named like 137_04.bvh).
Far too slow for a CPU (the reference needs ~8.6 s per step on 2 cores): run it on a GPU.
"""

from motiongan_jax.config import Config, DataConfig, ModelConfig, TrainConfig
from motiongan_jax.data import PAPER_STYLES


def get_config() -> Config:
    return Config(
        name="paper",
        data=DataConfig(
            data_dir=None,
            label_rule="cmu",
            styles=PAPER_STYLES,
            start_offset=1,
            control_point_interval=256,
            frame_nums=1024,
            frame_step=8,
            window_stride=3,
            val_modulus=0,
        ),
        model=ModelConfig(top=64, kw=5, w_dim=64, z_dim=64),
        train=TrainConfig(batch_size=24, num_steps=200_000, log_every=100, preview_every=5000,
                          checkpoint_every=20_000),
    )
