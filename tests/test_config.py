import dataclasses
from pathlib import Path

import pytest

from motiongan_jax import config as C

CONFIGS = Path(__file__).resolve().parents[1] / "configs"


@pytest.mark.parametrize("name", ["small", "tiny"])
def test_embedded_data_configs_load(name):
    assert C.load_config(CONFIGS / f"{name}.py").name == name


@pytest.mark.parametrize("name", ["paper", "bandai", "bandai_small"])
def test_real_data_configs_need_a_data_dir(name):
    with pytest.raises(C.ConfigError, match=r"data\.data_dir"):
        C.load_config(CONFIGS / f"{name}.py")


def test_paper_config_is_the_papers(tmp_path):
    import importlib.util

    spec = importlib.util.spec_from_file_location("paper_cfg", CONFIGS / "paper.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    cfg = C.override(mod.get_config(), [f"data.data_dir={tmp_path}"])
    C.validate(cfg)
    assert (cfg.train.batch_size, cfg.data.window_T, cfg.train.num_steps) == (24, 128, 200_000)
    assert len(cfg.data.styles) == 28 and cfg.data.styles[0] == "Cat" and cfg.data.styles[-1] == "Sneaky"
    assert (cfg.train.lr_d, cfg.train.lr_g, cfg.train.beta1, cfg.train.beta2) == (1e-4, 2e-4, 0.5, 0.999)


def test_override_types_and_errors():
    cfg = C.load_config(CONFIGS / "tiny.py")
    cfg2 = C.override(cfg, ["train.batch_size=8", "train.lr_g=0.001", "data.rotate=False",
                            "data.fps_factors=(1.0,)", "name=x"])
    assert cfg2.train.batch_size == 8 and cfg2.train.lr_g == 0.001 and cfg2.data.rotate is False
    assert cfg2.data.fps_factors == (1.0,) and cfg2.name == "x"
    assert C.override(cfg, ["data.fps_factors=1.5"]).data.fps_factors == (1.5,)
    # booleans from true/false; "none" is None only for fields that may be None
    assert C.override(cfg, ["model.d_cond=true"]).model.d_cond is True
    assert C.override(cfg, ["compute.conv_impl=xla"]).compute.conv_impl == "xla"
    with pytest.raises(C.ConfigError, match="model.walker.output_prior"):
        C.override(cfg, ["model.walker.output_prior=none"])
    # the walker: off (the paper's G), on with every part, or one part set (made with the others on)
    assert C.override(cfg, ["model.walker=default"]).model.walker == C.WalkerConfig()
    assert C.override(cfg, ["model.walker.frame=world"]).model.walker == C.WalkerConfig(frame="world")
    assert C.override(C.small(), ["model.walker=None"]).model.walker is None
    with pytest.raises(C.ConfigError, match="model.walker: None"):
        C.override(cfg, ["model.walker=yes"])
    with pytest.raises(C.ConfigError, match="model.walker has: exact_bones, frame"):
        C.override(cfg, ["model.walker.stride=1"])
    assert C.override(cfg, ["data.data_dir=/x", "data.data_dir=none"]).data.data_dir is None
    assert C.config_hash(cfg) != C.config_hash(cfg2)
    assert C.config_hash(cfg) == C.config_hash(C.load_config(CONFIGS / "tiny.py"))
    with pytest.raises(C.ConfigError, match="train.nope"):
        C.override(cfg, ["train.nope=1"])
    with pytest.raises(C.ConfigError, match="train.batch_size"):
        C.override(cfg, ["train.batch_size=abc"])
    with pytest.raises(C.ConfigError, match="not of the form"):
        C.override(cfg, ["train.batch_size"])


@pytest.mark.parametrize("assignment, field", [
    ("data.frame_nums=60", "data.frame_nums"),  # T = 15, not a multiple of 8
    ("data.label_rule=bogus", "data.label_rule"),
    ("data.data_dir=/no/such/dir", "data.data_dir"),
    ("model.time_kernel=4", "model.time_kernel"),
    ("train.curve_points=3", "train.curve_points"),
    ("compute.conv_impl=cudnn", "compute.conv_impl"),
    ("compute.compute_dtype=float16", "compute.compute_dtype"),
    ("model.walker.frame=body", "model.walker.frame"),
    ("model.d_cond=projection", "model.d_cond"),
    ("model.walker.gait_phase=1", "model.walker.gait_phase"),
    ("train.w_g_skate=-1.0", "train.w_g_skate"),
    ("train.w_g_stride=1.0", "train.w_g_stride"),  # needs model.gait_phase
    ("train.w_g_rec=1.0", "train.w_g_rec"),  # likewise
    ("model.walker.gait_phase=false", "model.walker.stride_speed"),  # a walker whose stride follows speed
    ("train.g_ema_decay=1.0", "train.g_ema_decay"),
    ("train.g_ema_decay=-0.1", "train.g_ema_decay"),
])
def test_invalid_values_name_the_field(assignment, field):
    cfg = C.load_config(CONFIGS / "tiny.py")
    with pytest.raises(C.ConfigError, match=field.replace(".", r"\.")):
        C.validate(C.override(cfg, [assignment]))


def test_saved_configs_with_a_retired_option_off_still_load():
    from motiongan_jax.config import from_dict, to_dict

    d = to_dict(C.load_config(CONFIGS / "tiny.py"))
    d["model"]["phase_wavelengths_m"] = []  # what configs saved before its removal hold
    assert from_dict(d) == C.load_config(CONFIGS / "tiny.py")
    d["model"]["phase_wavelengths_m"] = [1.2]
    with pytest.raises(C.ConfigError, match="model.phase_wavelengths_m.*no longer exists"):
        from_dict(d)
    d = to_dict(C.load_config(CONFIGS / "tiny.py"))
    d["data"]["augment_fps"] = True  # FPS augmentation on: what data.fps_factors alone says now
    assert from_dict(d) == C.load_config(CONFIGS / "tiny.py")
    d["data"]["augment_fps"] = False
    with pytest.raises(C.ConfigError, match="data.augment_fps.*no longer exists"):
        from_dict(d)


def test_saved_configs_with_the_old_field_names_load_under_the_new_ones():
    """model.top and model.kw, as every config saved before their rename holds them, load as
    model.base_channels and model.time_kernel; the dict keeps the hash it was saved with."""
    old = C.to_dict(C.tiny())
    model = old["model"]
    old["model"] = {"top": 12, "kw": 3, **{k: v for k, v in model.items() if k not in ("base_channels", "time_kernel")}}
    saved_hash = C.config_hash(old)
    cfg = C.from_dict(old)
    assert (cfg.model.base_channels, cfg.model.time_kernel) == (12, 3)
    assert cfg == C.override(C.tiny(), ["model.base_channels=12", "model.time_kernel=3"])
    assert "top" in old["model"] and C.config_hash(old) == saved_hash  # upgrade copies, never edits


FIXTURES = Path(__file__).resolve().parent / "fixtures"


def test_presets_are_the_config_files_and_differ_from_the_paper_only_where_documented():

    for name, make in C.PRESETS.items():
        assert C.load_config(CONFIGS / f"{name}.py", check=False) == make() == C.preset(name)
        assert make().name == name
    paper, small = C.paper().model, C.small().model
    # the small model turns every model option on; the paper's keeps every default
    assert paper == C.ModelConfig(base_channels=64, time_kernel=5, w_dim=64, z_dim=64)
    assert small.walker == C.WalkerConfig() and (small.d_cond, small.latent_init) == (True, "torch_default")
    assert (small.walker.output_prior, small.walker.exact_bones, small.walker.gait_phase, small.walker.root_height,
            small.walker.stride_speed, small.walker.frame) == (True, True, True, True, True, "curve")
    assert C.bandai_small().model == small and C.bandai_small().data.frame_nums == 64
    with pytest.raises(C.ConfigError, match="unknown preset 'cpu'"):
        C.preset("cpu")


def test_each_option_lists_its_values_once_and_validate_reads_them():

    assert C.choices(C.GFrame) == ("world", "curve")
    for field, literal in (("model.walker.frame", C.GFrame), ("model.latent_init", C.LatentInit),
                           ("train.gan_loss", C.GanLoss), ("compute.conv_impl", C.ConvImpl),
                           ("compute.compute_dtype", C.ComputeDtype), ("data.label_rule", C.LabelRule)):
        for value in C.choices(literal):  # every listed value validates ...
            C.validate(C.override(C.tiny(), [f"{field}={value}"]), need_data=False)
        with pytest.raises(C.ConfigError, match=field.replace(".", r"\.") + ".*not one of"):
            C.validate(C.override(C.tiny(), [f"{field}=bogus"]))  # ... and nothing else


def test_a_run_config_written_before_the_compute_section_loads_as_the_small_preset():
    """tests/fixtures/run_config_cpu_before_presets.json: the config.json of `bin/train.py --config
    configs/cpu.py --steps 300` written by the code before the compute section, the booleans
    and the rename of cpu to small (with use_z, d_frame and length_unit still in it)."""
    import json

    from motiongan_jax.model import checkpoint

    meta = json.loads((FIXTURES / "run_config_cpu_before_presets.json").read_text())
    old = meta["config"]
    assert old["name"] == "cpu" and old["model"]["d_cond"] == "projection" and "conv_impl" in old["model"]
    cfg = C.from_dict(old)
    # fields added since take the values that keep the run's behaviour, not the preset's new ones
    assert cfg == C.override(C.small(), ["train.num_steps=300", "train.w_g_root_jerk=0", "train.w_g_joint_jerk=0",
                                        "train.rec_z=zero", "model.walker.stride_speed=false"])
    assert C.to_dict(C.from_dict(C.to_dict(cfg))) == C.to_dict(cfg)  # the new schema round-trips
    # the saved hash is the old dict's; the same config in the new schema hashes differently
    assert meta["config_hash"] == C.config_hash(old) != C.config_hash(cfg)
    # a run of the same config resumes from it: the model sections agree whole
    checkpoint.check_compatible(meta, {"model": C.to_dict(cfg)["model"], "window_T": cfg.data.window_T}, "here")
    with pytest.raises(checkpoint.CheckpointError, match="its model is"):
        checkpoint.check_compatible(meta, {"model": C.to_dict(C.override(cfg, ["model.d_cond=false"]))["model"]},
                                    "here")
    # a saved config that used a retired option, or an old value with no boolean, is refused
    for section, name, value in (("model", "d_frame", "window"), ("model", "use_z", "zeros"),
                                 ("model", "length_unit", 1.0), ("model", "output_prior", "bogus")):
        bad = json.loads(json.dumps(old))
        bad[section][name] = value
        with pytest.raises(C.ConfigError, match=f"{section}.{name}"):
            C.from_dict(bad)


def test_saved_configs_carry_their_schema_and_older_ones_load():
    """to_dict writes the schema number; a config without one is schema 1 (saved before
    model.walker): its flat walker fields load as model.walker; a walker saved before schema 3 has
    no stride that follows speed (then off by default); an unknown schema is refused."""
    small = C.small()
    d = C.to_dict(small)
    assert d["schema"] == C.SCHEMA == 3 and C.OLDEST_SCHEMA == 1
    one_stride = dataclasses.replace(small, model=dataclasses.replace(
        small.model, walker=dataclasses.replace(small.model.walker, stride_speed=False)))
    two = {**d, "schema": 2, "model": {**d["model"], "walker": {k: v for k, v in d["model"]["walker"].items()
                                                                 if k != "stride_speed"}}}
    assert C.from_dict(two) == one_stride and C.from_dict(d) == small
    old = {k: v for k, v in d.items() if k != "schema"}
    old["model"] = {**{k: v for k, v in d["model"].items() if k != "walker"},
                    "output_prior": True, "g_frame": "curve", "exact_bones": True, "gait_phase": True,
                    "root_height": True}
    assert C.from_dict(old) == one_stride
    paper = {k: v for k, v in C.to_dict(C.tiny()).items() if k != "schema"}
    paper["model"] = {**{k: v for k, v in paper["model"].items() if k != "walker"}, "g_frame": "world"}
    assert C.from_dict(paper).model.walker is None
    for bad in (4, "2", 0):
        with pytest.raises(C.ConfigError, match="schemas 1 to 3"):
            C.from_dict({**d, "schema": bad})
    with pytest.raises(C.ConfigError, match="unknown config entries: extra"):
        C.from_dict({**d, "extra": 1})
