"""A small variant that learns on 2 CPU cores in minutes, on the embedded default dataset.

Same architecture as the paper with a narrower channel base and a shorter window; the synthetic
walks are 60 fps, so frame_step 4 gives the paper's 15 Hz samples and T 32 is a 2.1 s window.
Learning rates, losses and initialisation are the paper's (a run with 5x the learning rates
diverged after 2,000 steps; docs/RESULTS.md).
"""

from motiongan_jax.config import Config, DataConfig, ModelConfig, TrainConfig


def get_config() -> Config:
    return Config(
        name="cpu",
        data=DataConfig(
            data_dir=None,
            label_rule="synthetic",
            start_offset=1,
            control_point_interval=128,
            frame_nums=128,
            frame_step=4,
            window_stride=2,
            val_modulus=5,
            val_remainder=0,
        ),
        model=ModelConfig(top=16, kw=5, w_dim=32, z_dim=32),
        train=TrainConfig(batch_size=16, num_steps=3000, log_every=50, preview_every=1000,
                          checkpoint_every=500),
    )
