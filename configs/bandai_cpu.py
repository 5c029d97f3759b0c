"""The small variant of configs/bandai.py: the cpu config's model and training on the Bandai Namco data.

Same data settings as bandai.py but T 32 (a 2.1 s window at 15 Hz), and every setting of
configs/cpu.py (docs/RESULTS.md); trains 5,000 steps on 2 CPU cores in about 15 minutes. Pass --data
../shared/data/bandai/dataset-2 (or dataset-1, or their parent for both).
"""

import dataclasses
from pathlib import Path

from motiongan_jax.config import load_config


def get_config():
    here = Path(__file__).resolve().parent
    bandai, cpu = load_config(here / "bandai.py", check=False), load_config(here / "cpu.py", check=False)
    return dataclasses.replace(bandai, name="bandai_cpu", data=dataclasses.replace(bandai.data, frame_nums=64),
                               model=cpu.model, train=cpu.train)
