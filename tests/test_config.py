from pathlib import Path

import pytest

from motiongan_jax.config import ConfigError, config_hash, load_config, override, validate

CONFIGS = Path(__file__).resolve().parents[1] / "configs"


@pytest.mark.parametrize("name", ["cpu", "tiny"])
def test_embedded_data_configs_load(name):
    assert load_config(CONFIGS / f"{name}.py").name == name


@pytest.mark.parametrize("name", ["paper", "bandai", "bandai_cpu"])
def test_real_data_configs_need_a_data_dir(name):
    with pytest.raises(ConfigError, match=r"data\.data_dir"):
        load_config(CONFIGS / f"{name}.py")


def test_paper_config_is_the_papers(tmp_path):
    import importlib.util

    spec = importlib.util.spec_from_file_location("paper_cfg", CONFIGS / "paper.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    cfg = override(mod.get_config(), [f"data.data_dir={tmp_path}"])
    validate(cfg)
    assert (cfg.train.batch_size, cfg.data.window_T, cfg.train.num_steps) == (24, 128, 200_000)
    assert len(cfg.data.styles) == 28 and cfg.data.styles[0] == "Cat" and cfg.data.styles[-1] == "Sneaky"
    assert (cfg.train.lr_d, cfg.train.lr_g, cfg.train.beta1, cfg.train.beta2) == (1e-4, 2e-4, 0.5, 0.999)


def test_override_types_and_errors():
    cfg = load_config(CONFIGS / "tiny.py")
    cfg2 = override(cfg, ["train.batch_size=8", "train.lr_g=0.001", "data.rotate=False",
                          "data.fps_factors=(1.0,)", "name=x"])
    assert cfg2.train.batch_size == 8 and cfg2.train.lr_g == 0.001 and cfg2.data.rotate is False
    assert cfg2.data.fps_factors == (1.0,) and cfg2.name == "x"
    assert override(cfg, ["data.fps_factors=1.5"]).data.fps_factors == (1.5,)
    # "none" is a value of string options, and None only for fields that may be None
    assert override(cfg, ["model.d_cond=none"]).model.d_cond == "none"
    assert override(cfg, ["model.output_prior=none"]).model.output_prior == "none"
    assert override(cfg, ["data.data_dir=/x", "data.data_dir=none"]).data.data_dir is None
    assert config_hash(cfg) != config_hash(cfg2)
    assert config_hash(cfg) == config_hash(load_config(CONFIGS / "tiny.py"))
    with pytest.raises(ConfigError, match="train.nope"):
        override(cfg, ["train.nope=1"])
    with pytest.raises(ConfigError, match="train.batch_size"):
        override(cfg, ["train.batch_size=abc"])
    with pytest.raises(ConfigError, match="not of the form"):
        override(cfg, ["train.batch_size"])


@pytest.mark.parametrize("assignment, field", [
    ("data.frame_nums=60", "data.frame_nums"),  # T = 15, not a multiple of 8
    ("data.label_rule=bogus", "data.label_rule"),
    ("data.data_dir=/no/such/dir", "data.data_dir"),
    ("model.kw=4", "model.kw"),
    ("train.curve_points=3", "train.curve_points"),
    ("model.conv_impl=cudnn", "model.conv_impl"),
    ("model.compute_dtype=float16", "model.compute_dtype"),
    ("model.d_cond=concat", "model.d_cond"),
    ("model.gait_phase=1", "model.gait_phase"),
    ("train.w_g_skate=-1.0", "train.w_g_skate"),
    ("train.w_g_stride=1.0", "train.w_g_stride"),  # needs model.gait_phase
    ("train.w_g_rec=1.0", "train.w_g_rec"),  # likewise
    ("train.g_ema_decay=1.0", "train.g_ema_decay"),
    ("train.g_ema_decay=-0.1", "train.g_ema_decay"),
])
def test_invalid_values_name_the_field(assignment, field):
    cfg = load_config(CONFIGS / "tiny.py")
    with pytest.raises(ConfigError, match=field.replace(".", r"\.")):
        validate(override(cfg, [assignment]))


def test_saved_configs_with_a_retired_option_off_still_load():
    from motiongan_jax.config import from_dict, to_dict

    d = to_dict(load_config(CONFIGS / "tiny.py"))
    d["model"]["phase_wavelengths_m"] = []  # what configs saved before its removal hold
    assert from_dict(d) == load_config(CONFIGS / "tiny.py")
    d["model"]["phase_wavelengths_m"] = [1.2]
    with pytest.raises(ConfigError, match="model.phase_wavelengths_m.*no longer exists"):
        from_dict(d)
