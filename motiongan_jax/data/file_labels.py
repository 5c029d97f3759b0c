"""Style labels from file names, file discovery and the train/validation split by trial number."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

from motiongan_jax import atomic

# CMU styled-walk trials (subjects 137 and 142) -> style, as the CMU database describes them.
CMU_TRIAL_STYLES: dict[str, str] = {
    "137_04": "Cat", "137_08": "Chicken", "137_12": "Dinosaur", "137_16": "Drunk",
    "137_20": "GanglyTeen", "137_24": "GracefulLady", "137_29": "Normal", "137_33": "OldMan",
    "137_38": "SexyLady", "137_42": "StrongMan",
    "142_01": "Childish", "142_02": "Clumsy", "142_03": "Clumsy", "142_04": "Cool",
    "142_05": "Depressed", "142_06": "Elated", "142_07": "Elderlyman", "142_08": "Happy",
    "142_09": "Joy", "142_10": "Lavish", "142_11": "Marching", "142_12": "Painfulleftknee",
    "142_13": "Relaxed", "142_14": "Rushed", "142_15": "Sad", "142_16": "Scared",
    "142_17": "Scared", "142_18": "Sexy", "142_19": "Shy", "142_20": "Singingintherainjump",
    "142_21": "Singingintherainjump", "142_22": "Sneaky",
}


class DataError(ValueError):
    """A dataset problem (no files, unknown label, mismatched skeletons); the message says which."""



@dataclasses.dataclass(frozen=True)
class FileLabel:
    style: str
    trial: int  # drives the train/validation split
    content: str = "walk"


_BANDAI = re.compile(r"^dataset-(\d+)_([A-Za-z-]+)_([A-Za-z-]+)_(\d+)$")
_CMU = re.compile(r"^(\d+)_(\d+)$")


def label_from_filename(path: str | Path, rule: str) -> FileLabel | None:
    """The style label (and trial number) a file's name gives under `rule`; None if it gives none."""
    stem = Path(path).stem
    if rule in ("paper", "synthetic"):
        if "_" not in stem:
            return None
        style, rest = stem.split("_", 1)
        digits = re.findall(r"\d+", rest)
        return FileLabel(style=style, trial=int(digits[-1]) if digits else 0)
    if rule in ("bandai", "bandai_session"):
        m = _BANDAI.match(stem)
        if not m:
            return None
        # bandai_session keeps the recording sessions apart ("d1_active" and "d2_active" are two
        # styles), like the paper's two actors
        style = m.group(3) if rule == "bandai" else f"d{int(m.group(1))}_{m.group(3)}"
        return FileLabel(style=style, trial=int(m.group(4)), content=m.group(2))
    if rule == "cmu":
        m = _CMU.match(stem)
        if not m:
            return None
        key = f"{int(m.group(1)):03d}_{int(m.group(2)):02d}"
        style = CMU_TRIAL_STYLES.get(key)
        return None if style is None else FileLabel(style=style, trial=int(m.group(2)))
    raise DataError(f"unknown label rule {rule!r}")


def discover(data_dir: str | Path, rule: str) -> list[tuple[Path, FileLabel]]:
    """Every *.bvh under data_dir (recursive, sorted) with its label. Unlabelled files are errors."""
    root = Path(data_dir)
    if not root.is_dir():
        raise DataError(f"data directory not found: {root}")
    files = sorted(root.rglob("*.bvh"))
    if not files:
        raise DataError(f"no .bvh files under {root}")
    out, unlabelled = [], []
    for f in files:
        label = label_from_filename(f, rule)
        (unlabelled if label is None else out).append(f if label is None else (f, label))
    if unlabelled:
        names = ", ".join(p.name for p in unlabelled[:5])
        raise DataError(
            f"{len(unlabelled)} file(s) under {root} have no style label under rule {rule!r} "
            f"(e.g. {names}); choose another data.label_rule or remove them")
    return out


def split_by_trial(entries, modulus: int, remainder: int):
    """Deterministic train/validation split: trial % modulus == remainder goes to validation."""
    if modulus == 0:
        return list(entries), []
    train = [e for e in entries if e[1].trial % modulus != remainder]
    val = [e for e in entries if e[1].trial % modulus == remainder]
    return train, val


def write_file_lists(out_dir: str | Path, train, val, root: str | Path | None = None) -> None:
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    for name, entries in (("train_files.txt", train), ("val_files.txt", val)):
        lines = [str(Path(p).relative_to(root)) if root else str(p) for p, _ in entries]
        atomic.write_text(out_dir / name, "".join(line + "\n" for line in lines))

