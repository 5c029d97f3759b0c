"""Inference exports (motiongan_jax/model/pretrained.py, bin/export_model.py) and the shipped model.

Exports are made from checkpoints of the tiny config with seeded random parameters (conftest's random_run),
with a moving average unlike the trained parameters, so a test can tell which set was exported.
"""

import hashlib
import io
import json
import zipfile

import chex
import jax
import numpy as np
import pytest
from conftest import load_cli, random_run, run_cli

from motiongan_jax.config import config_hash, from_dict, load_config, override
from motiongan_jax.data import curves
from motiongan_jax.generate import styles, user_curves, walk
from motiongan_jax.model import checkpoint, pretrained
from motiongan_jax.motion import bvh

SPEED = 1.2


def _cli(repo, name):
    return load_cli(name).main


@pytest.fixture(scope="module")
def ema_run(repo, tmp_path_factory):
    cfg = override(load_config(repo / "configs" / "tiny.py"), ["train.g_ema_decay=0.999", "train.seed=7"])
    return random_run(cfg, tmp_path_factory.mktemp("ema_run"), step=4)


@pytest.fixture(scope="module")
def exported(ema_run, tmp_path_factory):
    """(export path, its provenance, the run loaded with its moving average, with its raw G)."""
    out = tmp_path_factory.mktemp("export") / "model.npz"
    info = pretrained.export_run(ema_run, out)
    return out, info, checkpoint.load_run(ema_run), checkpoint.load_run(ema_run, params="raw")


def _entries(path) -> dict:
    with np.load(path, allow_pickle=False) as z:
        return {k: z[k] for k in z.files}


def _sha256(arrays, names) -> str:
    """The digest as the module doc defines it: name, dtype, shape, C-order bytes, in name order."""
    h = hashlib.sha256()
    for n in sorted(names):
        a = np.asarray(arrays[n])
        h.update(n.encode() + b"\0" + a.dtype.str.encode() + b"\0" + repr(a.shape).encode() + b"\0")
        h.update(a.tobytes(order="C"))
    return h.hexdigest()


def _walk(state, layout, meta, cfg, style="Happy", T=32):
    """G along a straight line of exactly T samples."""
    rate, names = walk.sample_rate(meta, cfg), list(meta["style_names"])
    line = curves.shape_curve("line", scale=(T - 1) * SPEED / rate + 1e-6)
    curve = user_curves.prepare_curve(user_curves.Curve(line, "line"), rate, SPEED)
    w = styles.spec_codes(state, [styles.parse_style(style, names)], names)
    return walk.generate_motion(state, layout, curve, w)


def test_export_holds_the_moving_average_and_generates_what_the_checkpoint_does(exported):
    out, info, (ck_state, ck_meta, ck_cfg, layout), (raw_state, *_) = exported
    state, meta, cfg, layout2 = pretrained.load_export(out)

    # the parameters are the moving average's, bit for bit, and nothing of D or the optimisers
    for a, b in zip(jax.tree.leaves(state.g_params), jax.tree.leaves(raw_state.g_ema_params), strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    assert state.d_params is None and state.opt_g_state is None and state.g_ema_params is None
    assert int(state.step) == int(ck_state.step)
    # provenance from the config it was trained with
    assert info["config_hash"] == ck_meta["config_hash"] == config_hash(from_dict(ck_meta["config"]))
    assert info["seed"] == 7 and info["params"] == "ema" and info["config_name"] == "tiny"
    assert info["steps"] == int(ck_state.step)
    assert info["source_commit"] is None or len(info["source_commit"]) == 40
    # meta: the checkpoint's, without the machine's data directory
    assert meta == {**ck_meta, "data_dir": None}
    assert layout2.joint_names == layout.joint_names and layout2.parents == layout.parents
    np.testing.assert_array_equal(layout2.rest_offsets_m, layout.rest_offsets_m)

    a, b = _walk(state, layout2, meta, cfg), _walk(ck_state, layout, ck_meta, ck_cfg)
    np.testing.assert_array_equal(a.positions, b.positions)

    # the digests are the documented ones, recomputed here from the file's entries
    z = _entries(out)
    params = [n for n in z if n.startswith("g/")]
    assert len(params) == len(jax.tree.leaves(state.g_params))
    assert str(z["params_sha256"]) == info["params_sha256"] == _sha256(z, params)
    assert str(z["sha256"]) == info["sha256"] == _sha256(z, [n for n in z if n != "sha256"])


def test_export_is_deterministic_and_raw_is_the_trained_g(exported, ema_run, tmp_path):
    out, info, (ck_state, ck_meta, _, _), (raw_state, *_) = exported
    again = tmp_path / "again.npz"
    assert pretrained.export_state(again, ck_state, ck_meta, params="ema") == info
    assert again.read_bytes() == out.read_bytes()  # same bytes, not only the same arrays
    raw_info = pretrained.export_state(tmp_path / "raw.npz", raw_state, ck_meta, params="raw")
    state = pretrained.load_export(tmp_path / "raw.npz")[0]
    for x, y in zip(jax.tree.leaves(state.g_params), jax.tree.leaves(raw_state.g_params), strict=True):
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))
    assert raw_info["params"] == "raw" and raw_info["params_sha256"] != info["params_sha256"]


def _rewrite(src, dst, change):
    """A copy of an export with change(entries) applied, the stored checksums left as they were."""
    z = _entries(src)
    change(z)
    with zipfile.ZipFile(dst, "w") as zf:
        for name, arr in z.items():
            buf = io.BytesIO()
            np.lib.format.write_array(buf, arr, allow_pickle=False)
            zf.writestr(name + ".npy", buf.getvalue())


def test_a_damaged_or_edited_export_is_refused(exported, tmp_path):
    good = exported[0]
    name = next(n for n in _entries(good) if n.startswith("g/"))

    def flip(z):
        z[name] = z[name].copy()
        z[name].flat[0] = np.nextafter(z[name].flat[0], np.float32(np.inf))  # one ulp

    def edit_meta(z):
        meta = json.loads(str(z["meta"]))
        meta["style_names"] = meta["style_names"][::-1]
        z["meta"] = np.array(json.dumps(meta))

    for i, change in enumerate((flip, edit_meta)):
        bad = tmp_path / f"bad{i}.npz"
        _rewrite(good, bad, change)
        with pytest.raises(pretrained.ExportError, match="fails its checksum"):
            pretrained.load_export(bad)
    cut = tmp_path / "cut.npz"
    cut.write_bytes(good.read_bytes()[: good.stat().st_size // 2])
    with pytest.raises(pretrained.ExportError, match="cannot be read"):
        pretrained.load_export(cut)
    with pytest.raises(pretrained.ExportError, match="not found"):
        pretrained.load_export(tmp_path / "missing.npz")
    (tmp_path / "text.npz").write_text("not a model")
    with pytest.raises(pretrained.ExportError, match="not an .npz \\(zip\\) file"):
        pretrained.load_export(tmp_path / "text.npz")
    np.savez(tmp_path / "other.npz", x=np.zeros(3))
    with pytest.raises(pretrained.ExportError, match="not a motiongan_jax export"):
        pretrained.load_export(tmp_path / "other.npz")


def test_load_model_chooses_a_run_or_an_export(exported, ema_run):
    out = exported[0]
    assert pretrained.load_model(model=out)[1]["config"]["name"] == "tiny"
    assert pretrained.load_model(workdir=ema_run)[2].name == "tiny"
    assert pretrained.model_meta(model=out)["style_names"] == pretrained.model_meta(workdir=ema_run)["style_names"]
    with pytest.raises(pretrained.ExportError, match="not both"):
        pretrained.load_model(workdir=ema_run, model=out)
    with pytest.raises(pretrained.ExportError, match="--step needs"):
        pretrained.load_model(model=out, step=4)
    with pytest.raises(pretrained.ExportError, match="--params raw needs"):
        pretrained.load_model(model=out, params="raw")


def test_export_cli_prints_provenance_and_checks_files(repo, ema_run, tmp_path, capsys):
    main = _cli(repo, "export_model")
    out = tmp_path / "m.npz"
    assert main(["--workdir", str(ema_run), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    info = json.loads(printed[: printed.rindex("}") + 1])
    assert info["sha256"] == pretrained.read_export(out).sha256 and info["seed"] == 7
    assert main(["--info", str(out)]) == 0
    assert json.loads(capsys.readouterr().out)["params_sha256"] == info["params_sha256"]
    assert main(["--workdir", str(tmp_path / "none"), "--out", str(tmp_path / "x.npz")]) == 2
    assert "no checkpoints" in capsys.readouterr().err and not (tmp_path / "x.npz").exists()
    assert main(["--workdir", str(ema_run), "--out", str(tmp_path / "no" / "x.npz")]) == 2
    with pytest.raises(SystemExit) as e:
        main(["--workdir", str(ema_run), "--out", str(tmp_path / "x.bvh")])
    assert e.value.code == 2


# ---------------------------------------------------------------------------------------------
# the shipped model


@pytest.fixture(scope="module")
def shipped():
    return pretrained.read_export(pretrained.SHIPPED_MODEL)


def test_shipped_model_matches_its_checksum_and_generates_finite_walks(repo, shipped):
    assert pretrained.SHIPPED_MODEL.stat().st_size < 8e6
    z = _entries(pretrained.SHIPPED_MODEL)
    assert _sha256(z, [n for n in z if n != "sha256"]) == shipped.sha256 == str(z["sha256"])
    assert _sha256(z, [n for n in z if n.startswith("g/")]) == shipped.params_sha256
    p = shipped.provenance
    # provenance: the config as trained, the small preset's with seed 0
    assert p["config_hash"] == config_hash(shipped.meta["config"]) and p["config_name"] == "small"
    assert from_dict(shipped.meta["config"]) == override(load_config(repo / "configs" / "small.py"), ["train.seed=0"])
    assert p["params"] == "ema" and p["steps"] > 0 and shipped.meta["data_dir"] is None
    state, meta, cfg, layout = pretrained.state_from_export(shipped)
    names = list(meta["style_names"])
    assert len(names) == 9 and "OldMan" in names
    gen_ = _walk(state, layout, meta, cfg, "OldMan - Normal + Marching", T=48)
    chex.assert_shape(gen_.positions, (1, 48, len(layout.joint_names), 3))
    assert np.isfinite(gen_.positions).all()
    # the body stays near the path (a trained model; generous bound) and every bone keeps its length
    off = np.linalg.norm(gen_.positions[0, :, 0, [0, 2]].T - gen_.curve[:, [0, 2]], axis=-1)
    assert off.max() < 0.5, off.max()
    bones = np.linalg.norm(gen_.positions[0, :, 1:] - gen_.positions[0][:, list(layout.parents[1:])], axis=-1)
    np.testing.assert_allclose(bones, np.broadcast_to(layout.bone_lengths_m, bones.shape), atol=1e-4)


def test_generate_cli_uses_the_shipped_model_without_a_workdir(repo, shipped, tmp_path, capsys):
    main = _cli(repo, "generate")
    assert main(["--list-styles"]) == 0
    assert capsys.readouterr().out.split() == list(shipped.meta["style_names"])
    out = tmp_path / "walk.bvh"
    rate = walk.sample_rate(shipped.meta, from_dict(shipped.meta["config"]))
    assert main(["--style", "Sad:0.3,Happy:0.7", "--curve", "line", "--length",
                 str(47 * SPEED / rate + 1e-6), "--out", str(out)]) == 0
    motion = bvh.read_bvh(out)
    assert motion.num_frames == 48 and motion.frame_time == pytest.approx(1 / 15)


def test_analyze_cli_uses_the_shipped_model_without_a_workdir(repo, shipped, tmp_path):
    assert _cli(repo, "analyze")(["--out", str(tmp_path / "a"), "--k", "2"]) == 0
    report = json.loads((tmp_path / "a" / "analysis.json").read_text())
    assert report["workdir"] is None and report["model"] == pretrained.SHIPPED_MODEL.name
    assert report["step"] == shipped.provenance["steps"] and report["style_names"] == shipped.meta["style_names"]


def test_an_export_of_the_old_schema_upgrades_to_the_same_weights(exported, tmp_path):
    """An export whose meta holds a schema-1 config (no schema number, the walker's parts as flat
    model fields, what every export before model.walker holds) loads, and `--upgrade` rewrites it
    in today's schema: the same weights and params_sha256, the old digests kept in its provenance."""
    from motiongan_jax.config import SCHEMA, WALKER_FIELDS, WALKER_OFF

    good = exported[0]
    old = tmp_path / "old.npz"

    def to_schema_1(z):
        meta = json.loads(str(z["meta"]))
        config = {k: v for k, v in meta["config"].items() if k != "schema"}
        model = dict(config["model"])
        walker = model.pop("walker") or WALKER_OFF
        model.update({old_name: walker[new] for old_name, new in WALKER_FIELDS.items()})
        meta["config"] = {**config, "model": model}
        z["meta"] = np.array(json.dumps(meta, sort_keys=True))

    _rewrite(good, old, to_schema_1)
    entries = _entries(old)
    entries["sha256"] = np.array(_sha256(entries, [n for n in entries if n != "sha256"]))  # a valid old file
    _rewrite(old, old, lambda z: z.update(sha256=entries["sha256"]))
    before = pretrained.read_export(old)
    assert "schema" not in before.meta["config"] and "g_frame" in before.meta["config"]["model"]
    new = tmp_path / "new.npz"
    assert run_cli("export_model", ["--upgrade", str(old), "--out", str(new)])[0] == 0
    after = pretrained.read_export(new)
    assert after.meta["config"]["schema"] == SCHEMA and "walker" in after.meta["config"]["model"]
    assert after.params_sha256 == before.params_sha256 == pretrained.read_export(good).params_sha256
    assert after.provenance["upgraded_from"] == {"config_hash": before.provenance["config_hash"],
                                                 "sha256": before.sha256}
    a, b = pretrained.load_export(old)[0], pretrained.load_export(new)[0]
    assert all(np.array_equal(x, y) for x, y in zip(jax.tree.leaves(a.g_params), jax.tree.leaves(b.g_params)))
    code, _, err = run_cli("export_model", ["--upgrade", str(tmp_path / "missing.npz"), "--out", str(new)])
    assert code == 2 and "not found" in err
