"""The docs name what exists: every backticked dotted name in docs/*.md and README.md that starts
with a part of the package (`train.step.make_train_step`, `motion.trajectory.velocity`) resolves to
a module or an attribute of one, and every config field (`train.w_g_stride`) is a field of its
section today or an option the record of retired options (docs/RESULTS.md) names."""

from __future__ import annotations

import dataclasses
import importlib
import re
from pathlib import Path

import pytest

from motiongan_jax import config

ROOT = Path(__file__).resolve().parents[1]
DOCS = sorted((ROOT / "docs").glob("*.md")) + [ROOT / "README.md"]
PARTS = {p.stem for p in (ROOT / "motiongan_jax").iterdir() if p.suffix == ".py" or (p / "__init__.py").exists()}
# a module's own name stands for it too (`curves.velocity`, `walk.generate_motion`): stem -> subpackages
SUBMODULES: dict[str, list[str]] = {}
for _p in sorted((ROOT / "motiongan_jax").glob("*/*.py")):
    if _p.stem != "__init__":
        SUBMODULES.setdefault(_p.stem, []).append(_p.parent.name)
NAME = re.compile(r"`([A-Za-z_]\w*(?:\.[A-Za-z_]\w*)+)(?:\(\))?`")
FILE_SUFFIX = re.compile(r"\.(py|md|json|jsonl|txt|npz|npy|png|gif|mp4|bvh|glb|gltf|toml|ipynb|js|html|css|csv)$")


def retired_fields() -> set[str]:
    """`section.field` names that docs/RESULTS.md's "Retired options" record and config.upgrade
    maps (old runs and exports name them)."""
    text = (ROOT / "docs" / "RESULTS.md").read_text(encoding="utf-8")
    record = text[text.index("### Retired options"):]
    names = {m.group(1) for m in NAME.finditer(record)}
    names |= {f"{s}.{n}" for s, fields in config.RETIRED.items() for n in fields}
    names |= {f"{s}.{n}" for s, n in config.MOVED}
    names |= {f"model.{n}" for n in config.WALKER_FIELDS}
    return names


def config_field(name: str) -> bool | None:
    """True/False for `section.field` of a config section; None when `name` is not of that form."""
    section, _, field = name.partition(".")
    sub, _, sub_field = field.partition(".")
    if section not in config.SECTIONS:
        return None
    cls = config.SECTIONS[section]
    if (section, sub) in config.SUBSECTIONS and sub_field:
        cls, field = config.SUBSECTIONS[(section, sub)], sub_field
    elif "." in field:
        return None
    fields = {f.name for f in dataclasses.fields(cls)}
    return field in fields or (field in dir(cls) and not field.startswith("_"))


def resolves(name: str) -> bool:
    """Whether motiongan_jax.<name> is a module, or an attribute path from the longest module
    prefix of it; a name that starts with a module's own name (`curves.velocity`) may stand in
    for any subpackage's module of that name."""
    parts = name.split(".")
    if parts[0] in SUBMODULES and parts[0] not in PARTS:
        return any(resolves(".".join([package] + parts)) for package in SUBMODULES[parts[0]])
    parts = parts[1:] if parts[0] == "motiongan_jax" else parts
    for i in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module("motiongan_jax." + ".".join(parts[:i]))
        except ModuleNotFoundError:
            continue
        for attr in parts[i:]:
            if not hasattr(obj, attr):
                return False
            obj = getattr(obj, attr)
        return True
    return False


def unresolved(paths, retired) -> list[str]:
    bad = []
    for path in paths:
        for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            for m in NAME.finditer(line):
                name = m.group(1)
                first = name.split(".")[0]
                if first not in PARTS | set(SUBMODULES) | {"motiongan_jax"} | set(config.SECTIONS) \
                        or FILE_SUFFIX.search(name):
                    continue
                as_field = config_field(name)
                ok = (as_field or name in retired) if as_field is not None and not resolves(name) else resolves(name)
                if not ok:
                    bad.append(f"{path.name}:{number}: {name}")
    return bad


def test_every_backticked_name_in_the_docs_exists():
    assert unresolved(DOCS, retired_fields()) == []


@pytest.mark.parametrize("text, bad", [
    ("`motion.trajectory.velocity`, `train.w_g_stride` and `model.walker.frame`", []),
    ("`model.walker.stride`", ["x.md:1: model.walker.stride"]),
    ("`data.curves.velocity` moved", ["x.md:1: data.curves.velocity"]),
    ("`train.w_g_nothing` and `model.d_feet`", ["x.md:1: train.w_g_nothing"]),
    ("`runs/small/config.json`, `np.asarray`", []),
])
def test_the_check_finds_what_it_looks_for(tmp_path, text, bad):
    (tmp_path / "x.md").write_text(text + "\n")
    assert unresolved([tmp_path / "x.md"], {"model.d_feet"}) == bad
