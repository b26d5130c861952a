"""What the Blender tests (test_blender_host.py, test_blender_extension.py) share: Blender's own
``pxr`` on ``sys.path`` (a Blender built as a Python module keeps it off), and world-space
points as pxr and as Blender see them. Import only in a Python with ``bpy``."""

import os
import sys

import bpy
import numpy as np

SITE = os.path.join(
    bpy.utils.system_resource("PYTHON"), "lib", "python%d.%d" % sys.version_info[:2], "site-packages"
)
if SITE not in sys.path:
    sys.path.append(SITE)

from pxr import UsdGeom  # noqa: E402

import shots  # noqa: E402, F401  (pxr must be importable first)

# Blender's z up -> y up: (x, y, z) -> (x, z, -y).
Z_TO_Y = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


def pxr_world(stage, path, t):
    """A mesh's points at time ``t`` in world space, metres, y up."""
    prim = stage.GetPrimAtPath(path)
    pts = np.array(UsdGeom.Mesh(prim).GetPointsAttr().Get(t), dtype=np.float64)
    m = np.array(UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(t), dtype=np.float64)
    world = (np.c_[pts, np.ones(len(pts))] @ m)[:, :3] * UsdGeom.GetStageMetersPerUnit(stage)
    return world @ Z_TO_Y if UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.z else world


def blender_world(obj, frame):
    """A Blender object's evaluated points at ``frame``, metres, y up."""
    scene = bpy.context.scene
    scene.frame_set(frame)
    ev = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
    mesh = ev.to_mesh()
    co = np.empty(len(mesh.vertices) * 3)
    mesh.vertices.foreach_get("co", co)
    ev.to_mesh_clear()
    m = np.array(ev.matrix_world)
    world = (np.c_[co.reshape(-1, 3), np.ones(len(co) // 3)] @ m.T)[:, :3]
    return world * scene.unit_settings.scale_length @ Z_TO_Y
