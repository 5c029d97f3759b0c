"""Generate styled walks along a curve with a trained MotionGAN.

  python bin/generate.py --workdir runs/small --style Happy --curve s_curve --out walk.bvh
  python bin/generate.py --workdir runs/small --style "Sad:0.3,Happy:0.7" --curve path.csv --out walk.gif
  python bin/generate.py --workdir runs/small --style "OldMan - Normal + Marching" --curve circle --out w.npz
  python bin/generate.py --workdir runs/small --figure interp --style Sad,Happy --curve line --length 8 --out fig.png
  python bin/generate.py --workdir runs/small --list-styles
  python bin/generate.py --style Happy --curve s_curve --out walk.gif     # the shipped model
  python bin/generate.py --style-from clip.bvh --curve circle --out like_clip.gif    # walk like this clip

--workdir: a training run (its latest checkpoint, or --step); --model: an export file
(bin/export_model.py); neither: the model shipped with the package (motiongan_jax/weights/).

--curve: a shape (line, circle, s_curve, figure8, corner; --scale and --length in metres), a CSV
or JSON file of x,z points in metres, or a BVH file (its pelvis path, at its own speed).
--style: a name, a mix "A:0.3,B:0.7" (weights normalised to sum 1), an expression "A - B + C",
a .npy/.txt file holding a raw w vector, or "random" (from --seed). --z zero (default: w =
LT(0, label) like the reference's inference), seed (one z from --seed) or K (K samples, K outputs).
--out by suffix: .bvh (metres, Y up; --bvh-units cm for centimetres; --bvh-hierarchy source,
the training skeleton's joints, or exact, every bone direction exact through zero-length branch
joints), .npz (joint positions in metres and metadata), .gif, .mp4 (needs ffmpeg or
imageio-ffmpeg), .png (pose strips). Several motions: .bvh/.npz get one file each (OUT_0.bvh,
...), .gif/.mp4/.png show them side by side. The whole curve is walked (up to the limits in
motiongan_jax/generate/: 10 km, 36,000 samples); long ones go through G in chunks, with a
progress line on stderr when that takes more than a few seconds.
.glb / .gltf: a skinned character (the skeleton, a body made from its bone lengths, one animation
per motion; metres, Y up, +Z forward). --rig RIG (a BVH file or a built-in rig: mixamo, smpl,
bandai) retargets .bvh and glTF output onto that skeleton (joints matched by name through the
built-in maps, or --rig-map MAP.json of role -> joint name; --rig-units when its units are not
guessed right); its notes give the feet's skate and floor penetration beside the model's.
--style-from CLIP.bvh (or an .npz of world positions, bin/prepare_data.py's): the clip's style,
recovered by style search (analysis/search.py) as a mix of the model's styles, which stderr prints
("style of CLIP: Sad:0.62,Happy:0.31,..."; give it to --style to walk it again without searching),
walked along --curve at the clip's own speed unless --speed is given. The clip must be on the
model's skeleton (its training data's joints and units) and walk for at least one window (2 s).
--figure styles|interp|arith: the paper's Fig. 4 (--style "A,B,C" or all styles), Fig. 6
(--style "A,B": α = 0, 1/4, 1/2, 3/4, 1) and Fig. 7 (--style "A - B + C": operands and result).
Notes (the curve's sampling, the BVH's best-fit error) go to stderr, written paths to stdout.
Errors: a message on stderr, exit status 2, and no output file.
"""

import argparse
import sys

from motiongan_jax.cli import add_model_arguments, use_compilation_cache


def _log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


class Progress:
    """`progress(done, total)` for generate_motion: a line on `stream` (default: sys.stderr as it
    is when the bar is made, not when this module was imported) per G call, once the generation
    has run for `delay` seconds (short ones stay quiet)."""

    def __init__(self, stream=None, delay: float = 2.0, clock=None):
        import time

        self.stream, self.delay, self.clock = stream or sys.stderr, delay, clock or time.monotonic
        self.t0 = self.clock()

    def __call__(self, done: int, total: int) -> None:
        elapsed = self.clock() - self.t0
        if elapsed < self.delay:
            return
        eta = elapsed / done * (total - done)
        bar = "#" * (20 * done // total)
        print(f"generating [{bar:<20}] {done}/{total} G calls, {elapsed:.0f} s, about {eta:.0f} s left",
              file=self.stream, flush=True)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_model_arguments(ap)
    ap.add_argument("--list-styles", action="store_true", help="print the model's style names and exit")
    ap.add_argument("--style", default=None)
    ap.add_argument("--style-from", default=None, metavar="CLIP",
                    help="a BVH clip (or .npz of world positions): walk in its recovered style")
    ap.add_argument("--search-steps", type=int, default=None, metavar="N",
                    help="with --style-from: Adam steps of the style search (default 30; fewer: faster, rougher)")
    ap.add_argument("--curve", default=None)
    ap.add_argument("--out", default=None)
    ap.add_argument("--length", type=float, default=None, help="shape curves: arc length in metres")
    ap.add_argument("--scale", type=float, default=2.0, help="shape curves: size in metres (default 2)")
    ap.add_argument("--speed", type=float, default=None,
                    help="walking speed in m/s (default 1.2; a BVH curve: its own)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--z", default="zero", help="zero (default), seed, or a number of samples K")
    ap.add_argument("--figure", choices=("styles", "interp", "arith"), default=None)
    ap.add_argument("--bvh-units", choices=("m", "cm"), default="m")
    ap.add_argument("--rig", default=None,
                    help="retarget onto another skeleton: a BVH file or a built-in rig (mixamo, smpl, bandai); "
                         "with --out .bvh, .glb or .gltf")
    ap.add_argument("--rig-map", default=None,
                    help="a JSON file of role -> joint name for --rig (overrides the built-in name maps)")
    ap.add_argument("--rig-units", default=None,
                    help="metres per unit of --rig's file: m, cm, mm, inch or a number (default: from its leg)")
    ap.add_argument("--bvh-hierarchy", choices=("source", "exact"), default="source",
                    help="source (default): the training skeleton's joints, bones leaving a joint with several "
                         "children best-fit; exact: every bone direction exact, zero-length branch joints added")
    args = ap.parse_args(argv)

    import numpy as np

    from motiongan_jax.data import curves
    from motiongan_jax.generate import limits, styles, user_curves, walk, writers

    if not 0 <= args.seed <= limits.MAX_SEED:  # the demo's API takes the same seeds
        ap.error(f"--seed must be an integer 0..{limits.MAX_SEED}, got {args.seed}")
    from motiongan_jax.analysis.style_space import AnalysisError
    from motiongan_jax.model import checkpoint, pretrained
    from motiongan_jax.motion import rigs
    from motiongan_jax.motion.bvh import BVHError
    from motiongan_jax.motion.gltf import GLTFError
    from motiongan_jax.motion.ik import IKError

    if args.rig is None and (args.rig_map or args.rig_units):
        ap.error("--rig-map and --rig-units go with --rig")
    errors = (limits.GenerateError, checkpoint.CheckpointError, curves.DegenerateCurveError,
              curves.CurveFileError, BVHError, IKError, rigs.RigError, GLTFError, AnalysisError, OSError)
    try:
        if args.list_styles:
            print("\n".join(pretrained.model_meta(args.workdir, args.step, args.model)["style_names"]))
            return 0
        missing = [f"--{n}" for n in ("curve", "out") if getattr(args, n) is None]
        if args.search_steps is not None and (args.style_from is None or not 1 <= args.search_steps <= 1000):
            ap.error("--search-steps goes with --style-from and must be 1..1000")
        if args.style_from is not None and (args.style is not None or args.figure):
            ap.error("--style-from gives the style: use it without --style and --figure")
        if args.style is None and args.style_from is None and args.figure != "styles":
            missing.insert(0, "--style (or --style-from)")
        if missing:
            ap.error(f"missing {', '.join(missing)} (or use --list-styles)")
        writers.check_output_path(args.out, rig=args.rig is not None)  # fail before the model is loaded
        rig = None if args.rig is None else rigs.load_rig(args.rig, map_path=args.rig_map, units=args.rig_units)
        use_compilation_cache()  # G compiled by an earlier run is loaded, not compiled again
        if args.speed is not None:
            limits.check_speed(args.speed)
        if args.curve in curves.SHAPES:
            user_curves.check_shape_size(args.curve, args.length, args.scale)
        z_arg = args.z
        state, meta, cfg, layout = pretrained.load_model(args.workdir, args.step, args.params, args.model)
        names = list(meta["style_names"])
        speed = args.speed
        if args.style_from is not None:
            found, clip_speed = _style_from(args.style_from, state, meta, cfg, layout, args.search_steps)
            args.style = found.mix_text()
            near = ", ".join(f"{n} ({d:.3g})" for n, d in found.nearest[:3])
            _log(f"style of {args.style_from}: {args.style} (nearest known styles: {near}; "
                 f"search {found.seconds:.1f} s)")
            if speed is None:
                speed = float(np.clip(clip_speed, *limits.SPEED_RANGE_M_PER_S))
                _log(f"walking at the clip's speed, {speed:.2f} m/s (--speed to change it)")
        if args.figure:
            panels = styles.figure_specs(args.figure, args.style, names, args.seed)
        else:
            spec = styles.parse_style(args.style, names, args.seed)
            panels = [(spec.text, spec)]
        z = styles.z_codes(state, z_arg, args.seed)
        rate = walk.sample_rate(meta, cfg)
        curve = user_curves.load_curve(args.curve, length=args.length, scale=args.scale,
                                   control_seconds=cfg.data.control_point_interval / float(meta["fps"]))
        curve_M = user_curves.prepare_curve(curve, rate, speed, log=_log)
        count = len(panels) * len(z)
        writers.check_output_size(args.out, len(curve_M), count)  # before any work
        w = styles.spec_codes(state, [s for _, s in panels], names, z)
        titles = [t if len(z) == 1 else f"{t} z{k}" for t, _ in panels for k in range(len(z))]
        zs = [z[k] for _ in panels for k in range(len(z))]
        generated = walk.generate_motion(state, layout, curve_M, w, progress=Progress())
        paths = writers.write_outputs(args.out, generated, titles, layout, rate, bvh_units=args.bvh_units,
                                      bvh_hierarchy=args.bvh_hierarchy, z_per_motion=zs, log=_log, rig=rig)
    except errors as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    for p in paths:
        print(p)
    return 0


def _style_from(path, state, meta, cfg, layout, steps=None):
    """(analysis.search.StyleFound, the clip's speed in m/s) of a clip file."""
    from motiongan_jax.analysis import clips, search, style_space
    from motiongan_jax.generate import walk

    root, pose, fps = clips.load_motion(path, meta, cfg, layout)
    target = clips.model_rate_windows(root, pose, fps, meta, cfg, layout, spread=search.WINDOWS, phase=True,
                                      source=str(path))
    codes = style_space.label_codes(state, meta["style_names"], k=1).zero_CxD
    found = search.search_style(state, codes, meta["style_names"], target, steps=steps or search.STEPS)
    return found, target.spacing_m * walk.sample_rate(meta, cfg)
