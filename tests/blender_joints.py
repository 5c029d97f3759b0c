"""Run inside Blender (tests/test_blender.py starts it): import each file with Blender's own
importer and write every bone's head in world space, frame by frame, as JSON.

    blender -b --factory-startup --python tests/blender_joints.py -- OUT.json FPS FILE[=SCALE] ...

FILE ending in .glb/.gltf goes through the glTF importer, .bvh through the BVH importer at
global_scale SCALE (metres per file unit); positions are Blender's (Z up), in metres. Each file
is imported into an empty scene of its own. Frames: every whole frame of the armature's action.
"""

import builtins
import json
import sys

import bpy


def import_file(path: str, scale: float):
    if path.endswith((".glb", ".gltf")):
        # Shading "Smooth": Debian's Blender 3.4 guesses flat faces ("Normals", the default) with
        # numpy's np.bool, which numpy 1.24 removed; the bones are the same either way.
        bpy.ops.import_scene.gltf(filepath=path, import_shading="SMOOTH")
    else:
        # Debian's Blender 3.4 runs on Python 3.11, which refuses its BVH importer's open(path, "rU")
        import io_anim_bvh.import_bvh as import_bvh

        import_bvh.open = lambda p, mode="r", *a, **k: builtins.open(p, mode.replace("U", ""), *a, **k)
        bpy.ops.import_anim.bvh(filepath=path, global_scale=scale, rotate_mode="NATIVE", use_fps_scale=False,
                                update_scene_fps=False, update_scene_duration=True)


def heads(path: str, scale: float, fps: int) -> dict:
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.fps = fps  # the glTF importer places a sample at time t on frame t * fps
    import_file(path, scale)
    armature = [o for o in scene.objects if o.type == "ARMATURE"]
    assert len(armature) == 1, [o.name for o in scene.objects]
    armature = armature[0]
    first, last = armature.animation_data.action.frame_range
    frames = list(range(int(round(first)), int(round(last)) + 1))
    out = []
    for f in frames:
        scene.frame_set(f)
        out.append([list(armature.matrix_world @ pb.head) for pb in armature.pose.bones])
    return {"bones": [pb.name for pb in armature.pose.bones], "frames": frames, "heads": out}


def main(argv):
    out, fps, files = argv[0], int(argv[1]), argv[2:]
    result = {"blender": bpy.app.version_string, "files": {}}
    for spec in files:
        path, _, scale = spec.partition("=")
        result["files"][path] = heads(path, float(scale or 1.0), fps)
    with open(out, "w") as fh:
        json.dump(result, fh)


main(sys.argv[sys.argv.index("--") + 1:])
