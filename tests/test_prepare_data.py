import shutil
import types

import numpy as np
import pytest
from conftest import run_cli

from motiongan_jax.motion import bvh, kinematics

FILES = ("dataset-2_walk_normal_001.bvh", "dataset-2_walk_elderly_002.bvh", "dataset-2_walk-turn-left_active_001.bvh")


@pytest.fixture()
def bandai_dir(shared_data, tmp_path):
    d = tmp_path / "bandai"
    d.mkdir()
    for name in FILES:
        shutil.copy(shared_data / "bandai" / "dataset-2" / name, d / name)
    return d


def _run(*args):
    """bin/prepare_data.py in this process: (returncode, stdout, stderr) as attributes."""
    code, out, err = run_cli("prepare_data", args)
    return types.SimpleNamespace(returncode=code, stdout=out, stderr=err)


def test_prepare_data_exports_world_positions(bandai_dir, tmp_path):
    out = tmp_path / "out.npz"
    res = _run(bandai_dir, "--out", out, "--labels", "bandai")
    assert res.returncode == 0, res.stderr
    z = np.load(out)
    names = sorted(FILES)
    assert list(z["source_files"]) == names
    assert list(z["style_names"]) == ["active", "elderly", "normal"]
    assert [z["style_names"][i] for i in z["clip_style"]] == [n.split("_")[2] for n in names]
    assert float(z["fps"]) == pytest.approx(30.0, rel=1e-4)
    assert z["positions"].shape[1:] == (len(z["joint_names"]), 3)
    assert z["clip_length"].sum() == z["positions"].shape[0]
    for k, name in enumerate(names):
        motion = bvh.read_bvh(bandai_dir / name)
        start, length = z["clip_start"][k], z["clip_length"][k]
        assert length == motion.num_frames
        expected = kinematics.world_positions(motion) * 0.01  # centimetres -> metres
        np.testing.assert_allclose(z["positions"][start:start + length], expected, atol=1e-5)
    assert list(z["parents"]) == list(bvh.read_bvh(bandai_dir / names[0]).skeleton.parents)


def test_prepare_data_malformed_file_writes_nothing(bandai_dir, tmp_path):
    bad = bandai_dir / "dataset-2_walk_sad_004.bvh"
    text = (bandai_dir / FILES[0]).read_text().splitlines()
    text[-1] = text[-1].rsplit(" ", 1)[0] + " abc"  # a non-numeric value in the last frame
    bad.write_text("\n".join(text) + "\n")
    out = tmp_path / "out.npz"
    res = _run(bandai_dir, "--out", out, "--labels", "bandai")
    assert res.returncode != 0
    assert bad.name in res.stderr and f":{len(text)}:" in res.stderr
    assert not out.exists() and not list(tmp_path.glob(".out.npz*"))
    res = _run(bandai_dir, "--out", out, "--labels", "bandai", "--skip-bad")
    assert res.returncode == 0 and out.exists() and bad.name in res.stderr
    assert len(np.load(out)["clip_length"]) == 3
