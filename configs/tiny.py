"""Tests only: the smallest shapes that exercise every layer (T 16, top 4, batch 2)."""

from motiongan_jax.config import Config, DataConfig, ModelConfig, TrainConfig


def get_config() -> Config:
    return Config(
        name="tiny",
        data=DataConfig(
            data_dir=None,
            label_rule="synthetic",
            start_offset=1,
            control_point_interval=32,
            frame_nums=64,
            frame_step=4,
            window_stride=8,
            val_modulus=5,
            val_remainder=0,
        ),
        model=ModelConfig(top=4, kw=5, w_dim=8, z_dim=8),
        train=TrainConfig(batch_size=2, num_steps=4, log_every=1, preview_every=0, checkpoint_every=2,
                          keep_checkpoints=2),
    )
