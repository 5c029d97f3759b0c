"""The paper's architecture on the Bandai Namco data (30 fps, centimetres, 20 joints -> 60 rows).

At 30 fps a step of 2 gives the paper's 15 Hz samples; T 64 is a 4.3 s window. The control-point
interval keeps the paper's ~2.1 s (256 frames at 120 fps = 64 frames at 30 fps).
Pass --data ../shared/data/bandai/dataset-2 (or dataset-1, or their parent for both).
"""

from motiongan_jax.config import Config, DataConfig, ModelConfig, TrainConfig


def get_config() -> Config:
    return Config(
        name="bandai",
        data=DataConfig(
            data_dir=None,
            label_rule="bandai",
            units_to_m=0.01,
            start_offset=0,
            control_point_interval=64,
            frame_nums=128,
            frame_step=2,
            window_stride=1,
            val_modulus=4,
            val_remainder=0,
        ),
        model=ModelConfig(top=64, kw=5, w_dim=64, z_dim=64),
        train=TrainConfig(batch_size=24, num_steps=100_000, log_every=100, preview_every=5000,
                          checkpoint_every=10_000),
    )
