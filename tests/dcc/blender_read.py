"""Reads a USD file the way an artist's Blender does, for clothsr's DCC test (tests/dcc.rs).

    python-with-bpy tests/dcc/blender_read.py FILE.usd OUT.json FRAME [FRAME...]

Imports FILE into an empty Blender scene (`bpy.ops.wm.usd_import`), and at each FRAME writes the
evaluated points of every mesh object to OUT.json as {object name: {frame: [[x, y, z], ...]}},
converted back from Blender's z-up to USD's y-up ((x, y, z) -> (x, z, -y)) and to metres.
Run with a Python that has `bpy` (PyPI `bpy`, Blender as a module), not with usd-core: the two
carry their own USD libraries.
"""
import json
import sys

import bpy


def main() -> int:
    path, out, frames = sys.argv[1], sys.argv[2], [int(f) for f in sys.argv[3:]]
    bpy.ops.wm.read_factory_settings(use_empty=True)
    result = bpy.ops.wm.usd_import(filepath=path, set_frame_range=True)
    if "FINISHED" not in result:
        print(f"{path}: Blender's USD import returned {result}", file=sys.stderr)
        return 1
    scene = bpy.context.scene
    scale = scene.unit_settings.scale_length
    meshes = [o for o in scene.objects if o.type == "MESH"]
    data = {o.name: {} for o in meshes}
    for f in frames:
        scene.frame_set(f)
        depsgraph = bpy.context.evaluated_depsgraph_get()
        for o in meshes:
            ev = o.evaluated_get(depsgraph)
            mesh = ev.to_mesh()
            world = ev.matrix_world
            pts = []
            for v in mesh.vertices:
                x, y, z = world @ v.co
                pts.append([x * scale, z * scale, -y * scale])
            data[o.name][str(f)] = pts
            ev.to_mesh_clear()
    with open(out, "w") as fh:
        json.dump({"blender": bpy.app.version_string, "meshes": data}, fh)
    return 0


if __name__ == "__main__":
    sys.exit(main())
