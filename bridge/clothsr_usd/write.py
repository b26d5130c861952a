"""Writing clothsr scenes and meshes to USD: y up, metres, time-sampled points with extents,
``primvars:st`` for material coordinates, clothsr's schema (version ``SCHEMA_VERSION``) for
garments, and their fabric also as a physics material in OpenUSD's deformable-physics names
(``PhysicsSurfaceDeformableMaterialAPI``, bound for purpose ``physics``), which Newton reads.

Every write goes to a temporary file beside the target, is validated with all of usd-core's
validators, and only then renamed over the target: a failed write leaves no partial file.
"""
import os
import pathlib
import shutil

import numpy as np
from pxr import Gf, Sdf, Usd, UsdGeom, UsdPhysics, UsdShade, Vt

from .common import (
    GARMENT_API,
    PANEL,
    SCHEMA_VERSION,
    SCHEMA_VERSION_KEY,
    SEAM,
    SOLVER_API,
    BadInput,
    valid_name,
)
from .read import FABRIC_ATTRS, PHYSICS_PURPOSE, SURFACE_MATERIAL_API, SURFACE_SIM_API
from .validate import validate

WORLD = "/World"
MATERIALS = f"{WORLD}/PhysicsMaterials"


def _temp_path(path: pathlib.Path) -> pathlib.Path:
    _remove_stale(path)
    return path.with_name(f".{path.stem}.clothsr-tmp-{os.getpid()}{path.suffix}")


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _remove_stale(path: pathlib.Path):
    """Removes the temporary files a killed writer of ``path`` left (their process is gone)."""
    for kind in ("tmp", "pub"):
        for f in path.parent.glob(f".{path.stem}.clothsr-{kind}-*{path.suffix}"):
            pid = f.name[len(f".{path.stem}.clothsr-{kind}-") : len(f.name) - len(path.suffix)]
            if pid.isdigit() and int(pid) != os.getpid() and not _pid_alive(int(pid)):
                try:
                    f.unlink()
                except OSError:
                    pass


def _format_args(path: pathlib.Path, ascii_: bool):
    if path.suffix == ".usd":
        return {"format": "usda" if ascii_ else "usdc"}
    return {}


def _extent(points: np.ndarray):
    lo, hi = points.min(axis=0), points.max(axis=0)
    return Vt.Vec3fArray([Gf.Vec3f(*map(float, lo)), Gf.Vec3f(*map(float, hi))])


def _set_fabric(prim: Usd.Prim, fabric: dict, edge_length: float):
    prim.AddAppliedSchema(GARMENT_API[0])
    for key, attr_name in FABRIC_ATTRS.items():
        ty = Sdf.ValueTypeNames.String if key == "name" else Sdf.ValueTypeNames.Double
        value = str(fabric[key]) if key == "name" else float(fabric[key])
        prim.CreateAttribute(attr_name, ty, custom=False).Set(value)
    prim.CreateAttribute("clothsr:edgeLength", Sdf.ValueTypeNames.Double, custom=False).Set(
        float(edge_length)
    )
    _physics_material(prim, fabric)


def _physics_material(prim: Usd.Prim, fabric: dict):
    """The fabric in OpenUSD's deformable-physics names: a material under ``MATERIALS`` bound
    to the garment for purpose physics; a mesh also gets the surface-deformable simulation API
    and its thickness. Stage units are metres and kilograms.

    One surface stretch stiffness stands for the mean of warp and weft; Young's modulus is it
    over the thickness; Poisson's ratio is 0, as the Baraff-Witkin stretch model has no
    coupling between the two directions."""
    stage = prim.GetStage()
    UsdGeom.Scope.Define(stage, MATERIALS)
    path = f"{MATERIALS}/{prim.GetName()}"
    k = 1
    while stage.GetPrimAtPath(path):
        k += 1
        path = f"{MATERIALS}/{prim.GetName()}_{k}"
    material = UsdShade.Material.Define(stage, path)
    mat = material.GetPrim()
    UsdPhysics.MaterialAPI.Apply(mat)
    mat.AddAppliedSchema(SURFACE_MATERIAL_API)
    t = float(fabric["thickness_m"])
    stretch = 0.5 * (float(fabric["stretch_warp_n_m"]) + float(fabric["stretch_weft_n_m"]))
    values = {
        "poissonsRatio": 0.0,
        "surfaceStretchStiffness": stretch,
        "surfaceShearStiffness": float(fabric["shear_n_m"]),
        "surfaceBendStiffness": float(fabric["bending_n_m"]),
    }
    if t > 0:
        values["density"] = float(fabric["areal_density_kg_m2"]) / t
        values["youngsModulus"] = stretch / t
    for name, value in values.items():
        mat.CreateAttribute(f"physics:{name}", Sdf.ValueTypeNames.Float, custom=False).Set(value)
    UsdShade.MaterialBindingAPI.Apply(prim).Bind(
        material, UsdShade.Tokens.weakerThanDescendants, PHYSICS_PURPOSE
    )
    if prim.IsA(UsdGeom.Mesh) and t > 0:
        prim.AddAppliedSchema("PhysicsDeformableBodyAPI")
        prim.AddAppliedSchema(SURFACE_SIM_API)
        # Cloth collides (with bodies, and itself); its rest shape is flat (the pattern).
        UsdPhysics.CollisionAPI.Apply(prim)
        prim.CreateAttribute(
            "physics:restBendAnglesDefault", Sdf.ValueTypeNames.Token, custom=False,
            variability=Sdf.VariabilityUniform,
        ).Set("flat")
        prim.CreateAttribute("physics:thicknesses", Sdf.ValueTypeNames.FloatArray, custom=False).Set(
            Vt.FloatArray([t])
        )
        prim.CreateAttribute(
            "physics:thicknesses:elementType", Sdf.ValueTypeNames.Token, custom=False,
            variability=Sdf.VariabilityUniform,
        ).Set("constant")


def _define_garment(stage: Usd.Stage, parent: str, g: dict):
    root = UsdGeom.Xform.Define(stage, f"{parent}/{valid_name(g['name'])}")
    prim = root.GetPrim()
    _set_fabric(prim, g["fabric"], 0.0)
    panel_paths = []
    for p in g["panels"]:
        panel = stage.DefinePrim(f"{prim.GetPath()}/{valid_name(p['name'])}", PANEL[0])
        xf = UsdGeom.Xformable(panel)
        xf.AddTranslateOp(UsdGeom.XformOp.PrecisionDouble).Set(
            Gf.Vec3d(*map(float, p["translation"]))
        )
        xf.AddRotateXYZOp(UsdGeom.XformOp.PrecisionDouble).Set(Gf.Vec3d(*map(float, p["rotation"])))
        panel.CreateAttribute("clothsr:vertices", Sdf.ValueTypeNames.Double2Array, custom=False).Set(
            Vt.Vec2dArray.FromNumpy(np.ascontiguousarray(p["vertices"], dtype=np.float64))
        )
        panel.CreateAttribute("clothsr:edgeEndpoints", Sdf.ValueTypeNames.Int2Array, custom=False).Set(
            Vt.Vec2iArray.FromNumpy(np.ascontiguousarray(p["edge_endpoints"], dtype=np.int32))
        )
        panel.CreateAttribute("clothsr:edgeCurveTypes", Sdf.ValueTypeNames.TokenArray, custom=False).Set(
            list(p["curve_types"])
        )
        panel.CreateAttribute("clothsr:edgeCurveParams", Sdf.ValueTypeNames.Double4Array, custom=False).Set(
            Vt.Vec4dArray.FromNumpy(np.ascontiguousarray(p["curve_params"], dtype=np.float64))
        )
        panel_paths.append(panel.GetPath())
    for k, s in enumerate(g["seams"]):
        seam = stage.DefinePrim(f"{prim.GetPath()}/seam_{k}", SEAM[0])
        seam.CreateRelationship("clothsr:panelA", custom=False).SetTargets([panel_paths[s["panel_a"]]])
        seam.CreateAttribute("clothsr:edgeA", Sdf.ValueTypeNames.Int, custom=False).Set(int(s["edge_a"]))
        seam.CreateRelationship("clothsr:panelB", custom=False).SetTargets([panel_paths[s["panel_b"]]])
        seam.CreateAttribute("clothsr:edgeB", Sdf.ValueTypeNames.Int, custom=False).Set(int(s["edge_b"]))
        seam.CreateAttribute("clothsr:reversed", Sdf.ValueTypeNames.Bool, custom=False).Set(
            bool(s["reversed"])
        )


def _define_mesh(stage: Usd.Stage, parent: str, m: dict):
    """A UsdGeom.Mesh; ``frames`` (T, N, 3) with ``times`` become time samples."""
    mesh = UsdGeom.Mesh.Define(stage, f"{parent}/{valid_name(m['name'])}")
    prim = mesh.GetPrim()
    mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.ascontiguousarray(m["counts"], dtype=np.int32)))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(np.ascontiguousarray(m["indices"], dtype=np.int32)))
    frames = np.ascontiguousarray(m["frames"], dtype=np.float32)
    times = m.get("times")
    points_attr = mesh.CreatePointsAttr()
    extent_attr = mesh.CreateExtentAttr()
    if times is None or len(times) <= 1 and frames.shape[0] == 1 and m.get("static", True):
        points_attr.Set(Vt.Vec3fArray.FromNumpy(frames[0]))
        extent_attr.Set(_extent(frames[0]))
    else:
        layer = stage.GetEditTarget().GetLayer()
        pa, ea = points_attr.GetPath(), extent_attr.GetPath()
        with Sdf.ChangeBlock():
            for t, pts in zip(times, frames):
                layer.SetTimeSample(pa, float(t), Vt.Vec3fArray.FromNumpy(pts))
                layer.SetTimeSample(ea, float(t), _extent(pts))
        # The first frame also as the default value, for tools that read the mesh at the
        # default time (Newton's importer does); every time code reads the samples.
        points_attr.Set(Vt.Vec3fArray.FromNumpy(frames[0]))
        extent_attr.Set(_extent(frames[0]))
    if m.get("st") is not None:
        st = UsdGeom.PrimvarsAPI(mesh).CreatePrimvar(
            "st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.vertex
        )
        st.Set(Vt.Vec2fArray.FromNumpy(np.ascontiguousarray(m["st"], dtype=np.float32)))
    if m.get("panel_ids") is not None:
        pid = UsdGeom.PrimvarsAPI(mesh).CreatePrimvar(
            "clothsr:panelId", Sdf.ValueTypeNames.IntArray, UsdGeom.Tokens.vertex
        )
        pid.Set(Vt.IntArray.FromNumpy(np.ascontiguousarray(m["panel_ids"], dtype=np.int32)))
    if m.get("fabric") is not None:
        _set_fabric(prim, m["fabric"], m.get("edge_length", 0.0))
        pairs = m.get("seam_pairs")
        if pairs is not None:
            # Created with its type: in a host whose USD loaded before clothsr's schema was
            # registered, the schema does not define it.
            prim.CreateAttribute("clothsr:seamPairs", Sdf.ValueTypeNames.Int2Array, custom=False).Set(
                Vt.Vec2iArray.FromNumpy(np.ascontiguousarray(pairs, dtype=np.int32).reshape(-1, 2))
            )
    if m.get("collider"):
        UsdPhysics.CollisionAPI.Apply(prim)
    if m.get("doc"):
        prim.SetDocumentation(str(m["doc"]))


def _build(stage: Usd.Stage, spec: dict) -> dict:
    """Defines everything of ``spec`` on an empty stage; returns {mesh name: prim path}."""
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    UsdPhysics.SetStageKilogramsPerUnit(stage, 1.0)
    layer = stage.GetRootLayer()
    layer.customLayerData = {**layer.customLayerData, SCHEMA_VERSION_KEY: SCHEMA_VERSION}
    stage.SetTimeCodesPerSecond(float(spec.get("fps", 30.0)))
    stage.SetFramesPerSecond(float(spec.get("fps", 30.0)))
    stage.SetStartTimeCode(float(spec.get("start", 0.0)))
    stage.SetEndTimeCode(float(spec.get("end", 0.0)))
    world = UsdGeom.Xform.Define(stage, WORLD)
    stage.SetDefaultPrim(world.GetPrim())
    if spec.get("doc"):
        stage.GetRootLayer().documentation = str(spec["doc"])
    groups = set()
    paths = {}
    for g in spec.get("garments", []):
        if "Garments" not in groups:
            UsdGeom.Scope.Define(stage, f"{WORLD}/Garments")
            groups.add("Garments")
        _define_garment(stage, f"{WORLD}/Garments", g)
    for m in spec.get("meshes", []):
        group = valid_name(m.get("group", "Meshes"))
        if group not in groups:
            UsdGeom.Scope.Define(stage, f"{WORLD}/{group}")
            groups.add(group)
        _define_mesh(stage, f"{WORLD}/{group}", m)
        paths[m["name"]] = f"{WORLD}/{group}/{valid_name(m['name'])}"
    solver = spec.get("solver")
    if solver is not None:
        scene = UsdPhysics.Scene.Define(stage, f"{WORLD}/PhysicsScene")
        g = np.asarray(solver["gravity"], dtype=np.float64)
        mag = float(np.linalg.norm(g))
        direction = g / mag if mag > 0 else np.array([0.0, -1.0, 0.0])
        scene.CreateGravityDirectionAttr(Gf.Vec3f(*map(float, direction)))
        scene.CreateGravityMagnitudeAttr(mag)
        prim = scene.GetPrim()
        prim.AddAppliedSchema(SOLVER_API[0])
        prim.CreateAttribute("clothsr:timeStep", Sdf.ValueTypeNames.Double, custom=False).Set(
            float(solver["dt"])
        )
    return paths


def _finish(tmp: pathlib.Path, target: pathlib.Path, path: str) -> list:
    issues = validate(str(tmp))
    errors = [i for i in issues if i[0] == "error"]
    if errors:
        text = "; ".join(f"{ident}: {msg}" for _, ident, msg in errors[:5])
        raise ValueError(f"{path}: the written stage fails usd-core validation: {text}")
    os.replace(tmp, target)
    return [f"{ident}: {msg}" for sev, ident, msg in issues if sev != "error"]


def write_stage(path: str, spec: dict) -> list:
    """Writes ``spec`` to ``path`` atomically; returns the validators' warnings.

    ``spec``: ``fps``, ``start``, ``end``, optional ``doc``, ``ascii``; ``garments`` (pattern
    garments as returned by ``read_stage``), ``meshes`` (dicts with ``name``, ``group``,
    ``counts``, ``indices``, ``frames`` (T, N, 3), ``times`` or None, optional ``st``,
    ``panel_ids``, ``seam_pairs``, ``fabric``, ``edge_length``, ``collider``, ``doc``), and
    ``solver`` (``gravity``, ``dt``) or None. Raises ValueError on validation errors.
    """
    target = pathlib.Path(path)
    tmp = _temp_path(target)
    if tmp.exists():
        tmp.unlink()
    layer = Sdf.Layer.CreateNew(str(tmp), _format_args(target, bool(spec.get("ascii"))))
    stage = Usd.Stage.Open(layer)
    try:
        _build(stage, spec)
        layer.Save()
        del stage, layer
        return _finish(tmp, target, path)
    finally:
        if tmp.exists():
            tmp.unlink()


class AnimationWriter:
    """Writes an animation frame by frame: static content first (``spec`` as for
    ``write_stage``), then ``write_frame`` adds a time sample of points (and extent) to named
    meshes. ``checkpoint`` publishes what is written so far at the target path (a consistent
    file, replaced atomically); ``close`` validates and publishes the final file."""

    def __init__(self, path: str, spec: dict, resume_until=None):
        self.path = path
        self.target = pathlib.Path(path)
        self.tmp = _temp_path(self.target)
        if self.tmp.exists():
            self.tmp.unlink()
        self.layer = Sdf.Layer.CreateNew(str(self.tmp), _format_args(self.target, bool(spec.get("ascii"))))
        self.stage = Usd.Stage.Open(self.layer)
        self.paths = _build(self.stage, spec)
        self.start = float(spec.get("start", 0.0))
        self.last = None
        # Meshes whose points come frame by frame through write_frame (not static, no times).
        self.framed = [m["name"] for m in spec.get("meshes", []) if not m.get("static") and "times" not in m]
        if resume_until is not None:
            self._resume(float(resume_until))

    def _resume(self, until: float):
        """Copies the time samples up to ``until`` of the animated meshes from the file already
        at the target (an interrupted run's last checkpoint). Fails when it lacks that frame."""
        old = Sdf.Layer.FindOrOpen(str(self.target)) if self.target.exists() else None
        if old is None:
            raise BadInput(f"{self.path}: cannot resume: the file is missing or unreadable")
        with Sdf.ChangeBlock():
            for name in self.framed:
                prim = self.paths[name]
                for attr in ("points", "extent"):
                    src = Sdf.Path(f"{prim}.{attr}")
                    times = [t for t in old.ListTimeSamplesForPath(src) if t <= until + 1e-9]
                    if attr == "points" and (not times or abs(max(times) - until) > 1e-9):
                        raise BadInput(f"{self.path}: cannot resume: {prim} has no frame {until:g}")
                    for t in times:
                        self.layer.SetTimeSample(src, t, old.QueryTimeSample(src, t))
        self.last = until

    def write_frame(self, time: float, points: dict):
        with Sdf.ChangeBlock():
            for name, pts in points.items():
                prim = self.paths[name]
                arr = np.ascontiguousarray(pts, dtype=np.float32)
                self.layer.SetTimeSample(Sdf.Path(f"{prim}.points"), float(time), Vt.Vec3fArray.FromNumpy(arr))
                self.layer.SetTimeSample(Sdf.Path(f"{prim}.extent"), float(time), _extent(arr))
        self.last = float(time)

    def _publish(self, validate_it: bool) -> list:
        if self.last is not None:
            self.stage.SetEndTimeCode(max(self.last, self.start))
        self.layer.Save()
        copy = self.target.with_name(f".{self.target.stem}.clothsr-pub-{os.getpid()}{self.target.suffix}")
        shutil.copyfile(self.tmp, copy)
        try:
            if validate_it:
                return _finish(copy, self.target, self.path)
            os.replace(copy, self.target)
            return []
        finally:
            if copy.exists():
                copy.unlink()

    def checkpoint(self):
        """Publishes the frames written so far (no validation: fast)."""
        self._publish(False)

    def close(self) -> list:
        """Validates and publishes the final file; returns the validators' warnings."""
        try:
            return self._publish(True)
        finally:
            del self.stage, self.layer
            if self.tmp.exists():
                self.tmp.unlink()
