"""Checks that Newton's USD importer reads the cloth clothsr writes: every cloth mesh of a
clothsr USD file imported by `newton.ModelBuilder.add_usd` with its vertex and triangle counts,
its mass (areal density × area), its stretch stiffness (the mean of clothsr's warp and weft) and
its bending stiffness. Exits 1 on a mismatch.

    bash tools/bench/setup-newton.sh
    tools/bench/.venv-newton/bin/pip install 'newton[importers]==1.8.*'
    clothsr mesh samples/sheet_sphere.usda --edge-mm 20 -o out/sheet.usda
    tools/bench/.venv-newton/bin/python tools/bench/newton_usd_import.py out/sheet.usda
"""
import sys
import warnings

import numpy as np
from pxr import Usd, UsdGeom

import newton


def main(path: str) -> int:
    stage = Usd.Stage.Open(path)
    builder = newton.ModelBuilder()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        builder.add_usd(stage)
    for w in caught:
        print(f"newton: {w.message}")
    cloth = [
        p
        for p in stage.Traverse()
        if p.IsA(UsdGeom.Mesh) and p.GetAttribute("clothsr:fabric:arealDensity")
    ]
    if not cloth:
        print(f"{path}: no clothsr cloth mesh")
        return 1
    mesh = UsdGeom.Mesh(cloth[0])
    points = np.asarray(mesh.GetPointsAttr().Get(), dtype=np.float64)
    tris = np.asarray(mesh.GetFaceVertexIndicesAttr().Get(), dtype=np.int64).reshape(-1, 3)
    area = 0.5 * np.linalg.norm(
        np.cross(points[tris[:, 1]] - points[tris[:, 0]], points[tris[:, 2]] - points[tris[:, 0]]),
        axis=1,
    ).sum()
    get = lambda name: float(cloth[0].GetAttribute(f"clothsr:fabric:{name}").Get())
    want = {
        "particles": len(points),
        "triangles": len(tris),
        "mass_kg": get("arealDensity") * area,
        "stretch_n_m": 0.5 * (get("stretchWarp") + get("stretchWeft")),
        "bending_n_m": get("bending"),
    }
    tri_materials = np.asarray(builder.tri_materials)
    bending = np.asarray(builder.edge_bending_properties)
    got = {
        "particles": builder.particle_count,
        "triangles": builder.tri_count,
        "mass_kg": float(np.asarray(builder.particle_mass).sum()),
        "stretch_n_m": float(tri_materials[:, 0].mean()) if len(tri_materials) else 0.0,
        "bending_n_m": float(bending[:, 0].mean()) if len(bending) else 0.0,
    }
    ok = True
    for key, value in want.items():
        match = abs(got[key] - value) <= 1e-5 * max(abs(value), 1e-12)
        ok &= match
        print(f"{key}: clothsr {value:.6g}, newton {got[key]:.6g} {'ok' if match else 'MISMATCH'}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1]))
