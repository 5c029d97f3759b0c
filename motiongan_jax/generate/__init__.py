"""Generation from a trained model: styles, user curves, walking a curve, and the output writers.

The pieces bin/generate.py strings together (each usable on its own):

    styles.parse_style(text, style_names, seed)   -> StyleSpec     a label, mix, expression, w file, random
    styles.spec_codes(state, specs, names, z)     -> w (N, w_dim)  in w space, z = 0 by default
    user_curves.load_curve(text, length, scale)   -> Curve         a shape, a CSV/JSON file or a BVH root path
    user_curves.prepare_curve(curve, rate, speed) -> (M, 3)        equal spacing, every sample of the curve
    walk.generate_motion(state, layout, curve, w) -> Generated     G (in chunks if long), integration, floor
    writers.write_outputs(out, generated, ...)                     .bvh / .glb / .gltf / .npz / .gif / .mp4 / .png
                                                                   (rig=: .bvh and glTF on another skeleton)
    stream.Walker(state, layout, w, rate)          feed_steps / feed_points, then advance(n): the
                                                   next n samples of a walk steered as it goes
"""
