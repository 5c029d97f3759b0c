"""`bin/train.py --dry-run`: parameter counts and layer shapes, from abstract shapes only.

With data (a data directory, or the embedded dataset) the skeleton and styles are the dataset's.
Without it, the CMU label rules ("cmu", "paper") describe the model from the config alone: the
skeleton is CMU's 31-joint hierarchy (the one every CMU file has, in synthetic.cmu_skeleton,
which keeps 28 joints / 81 rows) and the styles are data.styles (the paper config lists its 28),
or for "cmu" every style of the CMU trial table. Parameter counts depend only on the number of
joints and styles, so they are the paper's model exactly; the Bandai rules take their skeleton
and styles from the files and need --data.
"""

from __future__ import annotations

import jax
from flax import nnx

from motiongan_jax.config import Config
from motiongan_jax.data import clip_cache, file_labels, synthetic
from motiongan_jax.model import build as model_build
from motiongan_jax.motion.representation import layout_from_skeleton
from motiongan_jax.nn import count_params


def model_source(cfg: Config):
    """(layout, style names, a line saying where they came from) for the dry run."""
    d = cfg.data
    if d.data_dir is not None or d.label_rule == "synthetic":
        dataset = clip_cache.load_dataset(d)
        return dataset.layout, dataset.style_names, (
            f"data {dataset.data_dir} ({len(dataset.train)} train / {len(dataset.val)} val clips, "
            f"{dataset.num_styles} styles, {dataset.fps:g} fps)")
    if d.label_rule not in ("cmu", "paper"):
        raise file_labels.DataError(f"--dry-run without data: label rule {d.label_rule!r} takes its skeleton and "
                             f"styles from the files; pass --data DIR")
    if d.styles:
        styles, where = tuple(d.styles), "data.styles"
    elif d.label_rule == "cmu":
        styles, where = tuple(sorted(set(file_labels.CMU_TRIAL_STYLES.values()))), "the CMU trial table (data.py)"
    else:
        raise file_labels.DataError("--dry-run without data: label rule 'paper' takes its styles from the file "
                             "names; set data.styles or pass --data DIR")
    layout = layout_from_skeleton(synthetic.cmu_skeleton(), synthetic.UNITS_TO_M)
    return layout, styles, (
        f"no data given: CMU's skeleton (its 31-joint hierarchy as every CMU file has it, "
        f"motiongan_jax/data/synthetic.py) and the {len(styles)} styles of {where}")


def describe(cfg: Config) -> str:
    layout, style_names, source = model_source(cfg)
    num_styles = len(style_names)
    g, d = nnx.eval_shape(
        lambda: model_build.build_models(cfg, layout.num_rel_joints, num_styles, jax.random.key(0), layout))
    lines = [
        f"config {cfg.name}: {source}",
        f"skeleton: {layout.num_joints} kept joints -> {layout.num_rows} rows; window T = {cfg.data.window_T}, "
        f"batch {cfg.train.batch_size}; {num_styles} styles",
        f"generator: {count_params(g):,} parameters",
        f"discriminator: {count_params(d):,} parameters (spectral-norm vectors not counted)",
        "",
        "parameter shapes:",
    ]
    for name, module in (("G", g), ("D", d)):
        for path, leaf in jax.tree_util.tree_flatten_with_path(nnx.state(module, nnx.Param))[0]:
            key = "/".join(str(getattr(p, "key", getattr(p, "name", p))) for p in path)
            lines.append(f"  {name} {key}: {tuple(leaf.shape)}")
    return "\n".join(lines)
