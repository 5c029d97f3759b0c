"""notebooks/style_space.ipynb, executed end to end so that it cannot rot.

The code cells run in order in one namespace, as a kernel runs them, with matplotlib's Agg
backend; like papermill, the test's parameters are applied right after the cell tagged
"parameters". No WORKDIR is given, so the notebook takes its fallback: the model shipped with the
package (motiongan_jax/weights). The parameters only
shrink what costs time (curve length, search steps); every cell runs as written.

IPython is not a test dependency (without it the notebook prints what it would show); stand-ins
for the IPython.display names record what the notebook displays, so the test checks that the
figures and the animations really are shown inline.
"""

import base64
import io
import json
from pathlib import Path

import chex
import numpy as np
import pytest

NOTEBOOK = Path(__file__).resolve().parents[1] / "notebooks" / "style_space.ipynb"
PARAMS = dict(CURVE_LENGTH_M=1.4, SEARCH_STEPS=3)


def _notebook() -> dict:
    return json.loads(NOTEBOOK.read_text(encoding="utf-8"))


def _code_cells(nb):
    return [c for c in nb["cells"] if c["cell_type"] == "code"]


def test_notebook_is_stored_clean_and_parameterised():
    nb = _notebook()
    assert nb["nbformat"] == 4
    cells = _code_cells(nb)
    for c in cells:
        assert c["outputs"] == [] and c["execution_count"] is None, "commit the notebook without outputs"
        for line in "".join(c["source"]).splitlines():
            assert not line.lstrip().startswith(("%", "!")), f"IPython-only syntax: {line!r}"
    first = "".join(cells[0]["source"])
    assert "parameters" in cells[0]["metadata"].get("tags", [])
    assert 'WORKDIR = os.environ.get("MOTIONGAN_NOTEBOOK_WORKDIR") or None' in first
    unknown = set(PARAMS) - {line.split("=")[0].strip() for line in first.splitlines() if "=" in line}
    assert not unknown, f"the test sets parameters the notebook does not have: {unknown}"


class _Shown:
    def __init__(self, kind, data=None, **kwargs):
        self.kind, self.data, self.kwargs = kind, data, kwargs


def _recording_display(shown: list) -> dict:
    """Stand-ins for the names the notebook imports from IPython.display, recording what is shown.
    (Put into the notebook's namespace, not sys.modules: flax's treescope imports IPython.core
    when an `IPython` module exists.)"""
    return {"HTML": lambda data=None, **kw: _Shown("html", data, **kw),
            "Markdown": lambda data=None, **kw: _Shown("markdown", data, **kw),
            "Image": lambda data=None, **kw: _Shown("image", data, **kw),
            "display": lambda *objs: shown.extend(objs)}


def _execute(nb, params: dict, display: dict) -> dict:
    """Code cells in order in one namespace; `params` after the "parameters" cell, `display`
    after the cell that defines the notebook's show_* helpers."""
    import matplotlib

    matplotlib.use("Agg", force=True)
    ns: dict = {"__name__": "__main__"}
    for i, cell in enumerate(nb["cells"]):
        if cell["cell_type"] != "code":
            continue
        source = "".join(cell["source"])
        exec(compile(source, f"{NOTEBOOK.name} cell {i}", "exec"), ns)
        if "parameters" in cell["metadata"].get("tags", []):
            ns.update(params)
        if "def show_animation(" in source:
            ns.update(display)
    return ns


@pytest.mark.slow
def test_notebook_runs_end_to_end_on_the_shipped_model(tmp_path, monkeypatch):
    from PIL import Image

    monkeypatch.delenv("MOTIONGAN_NOTEBOOK_WORKDIR", raising=False)
    monkeypatch.chdir(NOTEBOOK.parent)  # where Jupyter starts the kernel
    shown: list = []
    ns = _execute(_notebook(), {**PARAMS, "OUT": str(tmp_path / "out")}, _recording_display(shown))

    # the fallback loaded the shipped model
    from motiongan_jax.config import from_dict
    from motiongan_jax.model import pretrained

    shipped = pretrained.read_export(pretrained.SHIPPED_MODEL)
    assert ns["WORKDIR"] is None and ns["cfg"].name == "small" == from_dict(shipped.meta["config"]).name
    assert int(ns["state"].step) == shipped.provenance["steps"]
    names, codes = ns["names"], ns["codes"]
    C, D = codes.zero_CxD.shape
    assert C == len(names) and D == ns["cfg"].model.w_dim

    # PCA: ratios of the total variance, non-negative, sorted, summing to <= 1
    evr = np.asarray(ns["evr"], np.float64)
    chex.assert_shape(evr, (min(C * ns["K"], D),))
    assert np.all(evr >= -1e-7) and np.all(np.diff(evr) <= 1e-7) and evr.sum() <= 1 + 1e-5
    assert evr[0] > 0

    # interpolation: five codes from w_A to w_B, the same codes as the mix syntax
    w_ab, w_interp, T = ns["w_ab"], ns["w_interp"], len(ns["curve_T"])
    chex.assert_shape(w_interp, (len(ns["alphas"]), D))
    np.testing.assert_allclose(w_interp[[0, -1]], w_ab, rtol=1e-6, atol=1e-7)
    scale = float(np.abs(w_ab).max())
    assert scale > 1e-3  # styles differ
    np.testing.assert_allclose(w_interp, ns["w_mix"], atol=1e-5 * scale)
    J = len(ns["layout"].joint_names)
    chex.assert_shape(ns["gen_interp"].positions, (len(ns["alphas"]), T, J, 3))
    chex.assert_tree_all_finite(ns["gen_interp"].positions)

    # arithmetic: OldMan - Normal + Marching, as generate's expression parser computes it
    assert ns["spec"].text == "OldMan - Normal + Marching"
    w_ops = ns["w_ops"]
    np.testing.assert_allclose(ns["w_arith"], w_ops[0] - w_ops[1] + w_ops[2], atol=1e-6 * scale)
    np.testing.assert_allclose(ns["w_arith"], ns["w_parsed"], atol=1e-5 * scale)
    chex.assert_shape(ns["gen_arith"].positions, (4, T, J, 3))

    # style search on a held-out clip of the embedded dataset: a mix found from the best screened
    # styles, no worse than the best of them as it is
    from motiongan_jax.analysis import search

    assert Path(ns["clip"]).name == "OldMan_05.bvh"
    found = ns["found"]
    chex.assert_shape(found.w_D, (D,))
    assert found.loss_kind == "phase" and np.isfinite(found.final_loss_K).all()
    assert found.loss <= float(found.screen_C.min()) * 1.001
    assert abs(float(found.weights_C.sum()) - 1) < 1e-5 and found.starts[0] == names[int(np.argmin(found.screen_C))]
    chex.assert_shape(ns["target"].root_NxTx3, (search.WINDOWS, ns["cfg"].data.window_T, 3))

    # what was displayed: the two PCA figures, the nearest-styles table, three inline GIFs
    out = Path(ns["OUT"])
    kinds = [s.kind for s in shown]
    assert kinds == ["image", "markdown", "html", "html", "image", "html"], kinds
    assert [Path(s.kwargs["filename"]).name for s in shown if s.kind == "image"] == ["pca.png", "pca_search.png"]
    assert shown[1].data.startswith("# Nearest styles") and all(n in shown[1].data for n in names)
    frames = {"interpolation.gif": T, "arithmetic.gif": T,
              "search.gif": min(ns["cfg"].data.window_T, len(ns["along"]["curve_Tx3"]))}
    for s, (name, n_frames) in zip([s for s in shown if s.kind == "html"], frames.items()):
        prefix = '<img src="data:image/gif;base64,'
        assert s.data.startswith(prefix), s.data[:80]
        gif = base64.b64decode(s.data[len(prefix):s.data.index('"', len(prefix))])
        assert gif == (out / name).read_bytes()
        with Image.open(io.BytesIO(gif)) as im:
            assert im.format == "GIF" and im.n_frames == n_frames
    for name in ("pca.png", "pca_search.png"):
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
