"""Override layers for a USD shot (``clothsr run --layer``, the default for USD input).

Sublayered over the shot, the layer replaces each garment with its fine animated mesh at the
garment's own prim path: the prim becomes a ``Mesh`` (a pattern garment's panels and seams, and
a mesh garment's subsets, are deactivated), with the fine topology, ``points``, ``normals``,
``velocities`` and ``extent`` per frame in the prim's own space, units and up axis,
``primvars:st`` in the shot's convention (a mesh garment's own coordinates; a pattern's material
coordinates scaled to 0..1) and ``primvars:clothsr:materialCoords`` in metres. Nothing else of
the shot is copied; the coarse mesh is not written. The shot's primvars and topology attributes
the fine mesh would contradict (other UV sets, skinning weights, creases) are blocked.

Long animations go to value clips: one file per ``clip_frames`` frames in ``<name>.clips/``
(each holding its last frame also as the next clip's first, so that motion blur interpolates
across the seam), with a manifest and the static content (``static``, defaults for readers at
the default time) there too; the layer itself stays small. Every file is published atomically;
``close`` validates the shot composed with the layer before publishing the final layer.
"""
import os
import pathlib
import shutil

import numpy as np
from pxr import Kind, Sdf, Usd, UsdGeom, Vt

from .common import (
    LAYER_FOR_KEY,
    PANEL,
    SCHEMA_VERSION,
    SCHEMA_VERSION_KEY,
    SEAM,
    BadInput,
    compose,
    open_stage,
    stage_frame,
    write_composed,
)
from .validate import validate
from .write import _extent, _format_args, _temp_path

MATERIAL_PRIMVAR = "clothsr:materialCoords"
# Attributes of the shot's mesh that the fine mesh's topology would contradict.
TOPOLOGY_DEPENDENT = (
    "accelerations",
    "holeIndices",
    "cornerIndices",
    "cornerSharpnesses",
    "creaseIndices",
    "creaseLengths",
    "creaseSharpnesses",
)
ANIMATED = ("points", "normals", "velocities", "extent")


def _vertex_normals(points: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """Area-weighted vertex normals."""
    a, b, c = points[tris[:, 0]], points[tris[:, 1]], points[tris[:, 2]]
    face = np.cross(b - a, c - a)
    n = np.zeros_like(points)
    for k in range(3):
        np.add.at(n, tris[:, k], face)
    length = np.linalg.norm(n, axis=1, keepdims=True)
    return (n / np.where(length > 0, length, 1.0)).astype(np.float32)


def _publish(tmp: pathlib.Path, target: pathlib.Path):
    copy = target.with_name(f".{target.stem}.clothsr-pub-{os.getpid()}{target.suffix}")
    shutil.copyfile(tmp, copy)
    os.replace(copy, target)


def _declare_animated(layer: Sdf.Layer, garments):
    """The animated attributes of each garment, declared in ``layer`` (a clip or the
    manifest)."""
    for g in garments:
        spec = Sdf.CreatePrimInLayer(layer, g.path)
        for name, ty in (
            ("points", Sdf.ValueTypeNames.Point3fArray),
            ("normals", Sdf.ValueTypeNames.Normal3fArray),
            ("velocities", Sdf.ValueTypeNames.Vector3fArray),
            ("extent", Sdf.ValueTypeNames.Float3Array),
        ):
            Sdf.AttributeSpec(spec, name, ty, Sdf.VariabilityVarying)


class _File:
    """One file of the output being written: a temporary layer published to ``target``."""

    def __init__(self, target: pathlib.Path, ascii_: bool):
        self.target = target
        self.tmp = _temp_path(target)
        if self.tmp.exists():
            self.tmp.unlink()
        self.layer = Sdf.Layer.CreateNew(str(self.tmp), _format_args(target, ascii_))
        self.dirty = True

    def publish(self):
        if self.dirty:
            self.layer.Save()
            _publish(self.tmp, self.target)
            self.dirty = False

    def drop(self):
        self.layer = None
        if self.tmp.exists():
            self.tmp.unlink()


class _Garment:
    def __init__(self, name: str, prim: Usd.Prim, mesh: dict):
        self.name = name
        self.prim = prim
        self.path = prim.GetPath()
        self.tris = np.ascontiguousarray(mesh["indices"], dtype=np.int32).reshape(-1, 3)
        self.counts = np.ascontiguousarray(mesh["counts"], dtype=np.int32)
        self.material = np.ascontiguousarray(mesh["st"], dtype=np.float64) if mesh.get("st") is not None else None
        self.first = np.ascontiguousarray(mesh["frames"][0], dtype=np.float64)
        self.panel_ids = mesh.get("panel_ids")
        self.seam_pairs = mesh.get("seam_pairs")
        self.edge_length = float(mesh.get("edge_length", 0.0))
        # The last two frames written (time, local points), for central-difference velocities.
        self.history = []


class LayerWriter:
    """Writes the fine garments of a run frame by frame as an override layer for the shot
    ``spec["over"]["input"]``; the interface of ``AnimationWriter``."""

    def __init__(self, path: str, spec: dict, resume_until=None):
        over = spec["over"]
        self.path = path
        self.target = pathlib.Path(path)
        self.ascii = bool(spec.get("ascii"))
        self.input = pathlib.Path(over["input"]).resolve()
        self.shot = open_stage(str(self.input))
        self.mpu, self.axes = stage_frame(self.shot, str(self.input))
        self.tcps = float(self.shot.GetTimeCodesPerSecond())
        self.start = float(spec.get("start", 0.0))
        self.end = float(spec.get("end", self.start))
        clip = int(over.get("clip_frames") or 0)
        self.clip = clip if clip > 0 and self.end - self.start > clip else 0
        meshes = {m["name"]: m for m in spec.get("meshes", [])}
        self.garments = []
        for name, prim_path in over["prims"].items():
            prim = self.shot.GetPrimAtPath(prim_path)
            if not prim or name not in meshes:
                raise BadInput(f"{self.input}: no garment prim {prim_path} for '{name}'")
            self.garments.append(_Garment(name, prim, meshes[name]))
        self.by_name = {g.name: g for g in self.garments}
        self.clips_dir = self.target.with_name(f"{self.target.stem}.clips")
        self.top = _File(self.target, self.ascii)
        if self.clip:
            self.clips_dir.mkdir(exist_ok=True)
            self.static = _File(self.clips_dir / "static.usdc", False)
            self.manifest = _File(self.clips_dir / "manifest.usda", True)
        else:
            self.static = self.top
            self.manifest = None
        self.chunks = {}  # clip index -> _File being written
        self.done_chunks = set()  # clip indices complete and published
        self.last = None
        self._build_static(doc=spec.get("doc"))
        if resume_until is not None:
            self._resume(float(resume_until))

    # -- layout --------------------------------------------------------------------------

    def _chunk_range(self, k: int):
        return self.start + k * self.clip, min(self.start + (k + 1) * self.clip, self.end)

    def _chunks_of(self, t: float):
        """The clips holding time ``t`` (two at a seam)."""
        if not self.clip:
            return []
        k = int((t - self.start) // self.clip)
        out = [k] if self._chunk_range(k)[0] <= t <= self._chunk_range(k)[1] else []
        if k > 0 and t <= self._chunk_range(k - 1)[1]:
            out.insert(0, k - 1)
        return [j for j in out if self._chunk_range(j)[0] < self.end or j == 0]

    def _chunk_file(self, k: int) -> _File:
        f = self.chunks.get(k)
        if f is None:
            f = _File(self.clips_dir / f"{self.target.stem}.{k:04d}.usdc", False)
            _declare_animated(f.layer, self.garments)
            self.chunks[k] = f
        return f

    def _stage_metadata(self, layer: Sdf.Layer):
        stage = Usd.Stage.Open(layer)
        UsdGeom.SetStageUpAxis(stage, UsdGeom.GetStageUpAxis(self.shot))
        UsdGeom.SetStageMetersPerUnit(stage, UsdGeom.GetStageMetersPerUnit(self.shot))
        stage.SetTimeCodesPerSecond(self.tcps)
        stage.SetFramesPerSecond(float(self.shot.GetFramesPerSecond()))
        stage.SetStartTimeCode(self.start)
        stage.SetEndTimeCode(self.end)
        default = self.shot.GetRootLayer().defaultPrim
        if default:
            layer.defaultPrim = default
        return stage

    def _build_static(self, doc):
        top = self.top.layer
        self._stage_metadata(top)
        top.customLayerData = {
            **top.customLayerData,
            SCHEMA_VERSION_KEY: SCHEMA_VERSION,
            LAYER_FOR_KEY: os.path.relpath(self.input, self.target.parent.resolve()),
        }
        if doc:
            top.documentation = f"{doc}; an override layer for {self.input.name}"
        if self.clip:
            top.subLayerPaths.append(f"./{self.clips_dir.name}/static.usdc")
            self._build_manifest()
        stage = Usd.Stage.Open(self.static.layer)
        for g in self.garments:
            self._define(stage, g)

    def _define(self, stage: Usd.Stage, g: _Garment):
        src = g.prim
        prim = stage.OverridePrim(g.path)
        prim.SetTypeName("Mesh")
        mesh = UsdGeom.Mesh(prim)
        mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
        mesh.CreateOrientationAttr(UsdGeom.Tokens.rightHanded)
        mesh.CreateDoubleSidedAttr(True)
        mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(g.counts))
        mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(g.tris.reshape(-1)))
        if not Usd.ModelAPI(src).GetKind():
            Usd.ModelAPI(prim).SetKind(Kind.Tokens.subcomponent)
        pv = UsdGeom.PrimvarsAPI(prim)
        written = {"primvars:st", f"primvars:{MATERIAL_PRIMVAR}", "primvars:clothsr:panelId"}
        # The fine mesh's resolution, its panels and its sewing, as a standalone stage has them.
        prim.CreateAttribute("clothsr:edgeLength", Sdf.ValueTypeNames.Double, custom=False).Set(g.edge_length)
        if g.panel_ids is not None:
            pv0 = UsdGeom.PrimvarsAPI(prim).CreatePrimvar(
                "clothsr:panelId", Sdf.ValueTypeNames.IntArray, UsdGeom.Tokens.vertex
            )
            pv0.Set(Vt.IntArray.FromNumpy(np.ascontiguousarray(g.panel_ids, dtype=np.int32)))
        if g.seam_pairs is not None:
            prim.CreateAttribute("clothsr:seamPairs", Sdf.ValueTypeNames.Int2Array, custom=False).Set(
                Vt.Vec2iArray.FromNumpy(np.ascontiguousarray(g.seam_pairs, dtype=np.int32).reshape(-1, 2))
            )
        if g.material is not None:
            if src.IsA(UsdGeom.Mesh):
                st = g.material  # the shot's own texture coordinates, carried through
            else:
                lo = g.material.min(axis=0)
                size = float((g.material.max(axis=0) - lo).max()) or 1.0
                st = (g.material - lo) / size
            pv.CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.vertex).Set(
                Vt.Vec2fArray.FromNumpy(np.ascontiguousarray(st, dtype=np.float32))
            )
            pv.CreatePrimvar(MATERIAL_PRIMVAR, Sdf.ValueTypeNames.Float2Array, UsdGeom.Tokens.vertex).Set(
                Vt.Vec2fArray.FromNumpy(np.ascontiguousarray(g.material, dtype=np.float32))
            )
        mesh.CreateNormalsAttr().SetMetadata("interpolation", UsdGeom.Tokens.vertex)
        # What of the shot's prim the fine mesh would contradict: blocked.
        for attr in src.GetAuthoredAttributes():
            name = attr.GetName()
            if name in written:
                continue
            if name.startswith("primvars:") or name in TOPOLOGY_DEPENDENT:
                prim.CreateAttribute(name, attr.GetTypeName(), custom=attr.IsCustom()).Block()
        if "SkelBindingAPI" in src.GetAppliedSchemas():
            prim.RemoveAppliedSchema("SkelBindingAPI")
        for child in src.GetChildren():
            if child.GetTypeName() in PANEL + SEAM + ("GeomSubset",):
                stage.OverridePrim(child.GetPath()).SetActive(False)
        # Readers at the default time see the first frame.
        local = self._local(g, self.start, g.first)
        mesh.GetPointsAttr().Set(Vt.Vec3fArray.FromNumpy(local))
        mesh.GetExtentAttr().Set(_extent(local))
        mesh.GetNormalsAttr().Set(Vt.Vec3fArray.FromNumpy(_vertex_normals(local, g.tris)))
        mesh.CreateVelocitiesAttr().Set(Vt.Vec3fArray.FromNumpy(np.zeros_like(local)))

    def _build_manifest(self):
        _declare_animated(self.manifest.layer, self.garments)

    def _clip_metadata(self):
        """Points the layer's garments at the clips published so far."""
        ks = sorted(self.done_chunks | set(self.chunks))
        if not ks:
            return
        stage = Usd.Stage.Open(self.top.layer)
        rel = self.clips_dir.name
        for g in self.garments:
            clips = Usd.ClipsAPI(stage.OverridePrim(g.path))
            clips.SetClipAssetPaths([Sdf.AssetPath(f"./{rel}/{self.target.stem}.{k:04d}.usdc") for k in ks])
            clips.SetClipPrimPath(str(g.path))
            clips.SetClipActive([(self._chunk_range(k)[0], i) for i, k in enumerate(ks)])
            clips.SetClipTimes([(self.start, self.start), (self.end, self.end)])
            clips.SetClipManifestAssetPath(Sdf.AssetPath(f"./{rel}/manifest.usda"))
        self.top.dirty = True

    # -- frames ----------------------------------------------------------------------------

    def _local(self, g: _Garment, time: float, world: np.ndarray) -> np.ndarray:
        """clothsr's points (metres, y up) in the garment prim's own space at ``time``."""
        stage_pts = (np.asarray(world, dtype=np.float64) @ self.axes) / self.mpu
        m = np.array(
            UsdGeom.Xformable(g.prim).ComputeLocalToWorldTransform(Usd.TimeCode(time)), dtype=np.float64
        ).reshape(4, 4)
        inv = np.linalg.inv(m)
        return (stage_pts @ inv[:3, :3] + inv[3, :3]).astype(np.float32)

    def _layers_at(self, t: float):
        if not self.clip:
            return [self.top]
        return [self._chunk_file(k) for k in self._chunks_of(t)]

    def _set(self, g: _Garment, attr: str, t: float, value):
        for f in self._layers_at(t):
            f.layer.SetTimeSample(g.path.AppendProperty(attr), t, value)
            f.dirty = True

    def write_frame(self, time: float, points: dict):
        time = float(time)
        with Sdf.ChangeBlock():
            for name, pts in points.items():
                g = self.by_name[name]
                local = self._local(g, time, pts)
                self._set(g, "points", time, Vt.Vec3fArray.FromNumpy(local))
                self._set(g, "extent", time, _extent(local))
                self._set(g, "normals", time, Vt.Vec3fArray.FromNumpy(_vertex_normals(local, g.tris)))
                self._velocities(g, time, local)
        self.last = time

    def _velocities(self, g: _Garment, time: float, local: np.ndarray):
        """Backward difference at ``time``; the frame before gets its central difference."""
        h = g.history
        per_s = lambda a, ta, b, tb: ((a - b) * (self.tcps / (ta - tb))).astype(np.float32)  # noqa: E731
        if h:
            t1, p1 = h[-1]
            self._set(g, "velocities", time, Vt.Vec3fArray.FromNumpy(per_s(local, time, p1, t1)))
            if len(h) == 2:
                t0, p0 = h[0]
                self._set(g, "velocities", t1, Vt.Vec3fArray.FromNumpy(per_s(local, time, p0, t0)))
            else:
                self._set(g, "velocities", t1, Vt.Vec3fArray.FromNumpy(per_s(local, time, p1, t1)))
        else:
            self._set(g, "velocities", time, Vt.Vec3fArray.FromNumpy(np.zeros_like(local)))
        g.history = (h + [(time, local)])[-2:]

    def _resume(self, until: float):
        """Takes the frames up to ``until`` from the published files of an interrupted run."""
        if not self.target.exists():
            raise BadInput(f"{self.path}: cannot resume: the file is missing")
        sources = {}
        if self.clip:
            k = 0
            while self._chunk_range(k)[0] <= until:
                f = self.clips_dir / f"{self.target.stem}.{k:04d}.usdc"
                if not f.exists():
                    raise BadInput(f"{self.path}: cannot resume: {f} is missing")
                if self._chunk_range(k)[1] < until:
                    self.done_chunks.add(k)
                else:
                    sources[k] = f
                k += 1
        else:
            sources[None] = self.target
        for k, path in sources.items():
            old = Sdf.Layer.OpenAsAnonymous(str(path))
            dest = self.top if k is None else self._chunk_file(k)
            for g in self.garments:
                for attr in ANIMATED:
                    src = g.path.AppendProperty(attr)
                    for t in old.ListTimeSamplesForPath(src):
                        if t <= until + 1e-9:
                            dest.layer.SetTimeSample(src, t, old.QueryTimeSample(src, t))
        for g in self.garments:
            times = []
            for k, path in sources.items():
                layer = self.top.layer if k is None else self.chunks[k].layer
                times += [t for t in layer.ListTimeSamplesForPath(g.path.AppendProperty("points"))]
            times = sorted(set(times))
            if not times or abs(times[-1] - until) > 1e-9:
                raise BadInput(f"{self.path}: cannot resume: {g.path} has no frame {until:g}")
            layers = [self.top] if not self.clip else [self.chunks[k] for k in self._chunks_of(until)]
            for t in times[-2:]:
                pts = layers[-1].layer.QueryTimeSample(g.path.AppendProperty("points"), t)
                if pts is None:
                    pts = layers[0].layer.QueryTimeSample(g.path.AppendProperty("points"), t)
                g.history.append((t, np.array(pts, dtype=np.float32)))
        self.last = until

    # -- publishing --------------------------------------------------------------------------

    def _publish(self, final: bool) -> list:
        end = self.end if final else max(self.last if self.last is not None else self.start, self.start)
        self.top.layer.endTimeCode = end
        self.top.dirty = True
        warnings = []
        if self.clip:
            self.static.publish()
            self.manifest.publish()
            for k in sorted(self.chunks):
                self.chunks[k].publish()
            # Clips no later frame will touch are complete: written for good.
            for k in list(self.chunks):
                if self.last is not None and self._chunk_range(k)[1] < self.last:
                    self.chunks.pop(k).drop()
                    self.done_chunks.add(k)
            self._clip_metadata()
        if final:
            self.top.layer.Save()
            warnings = self._validate()
        self.top.publish()
        if final:
            write_composed(self.target, self.input, over=self.top.layer)
        return warnings

    def _validate(self) -> list:
        """Validates the shot composed with the layer (its temporary file); raises on errors
        the shot alone does not have."""
        check = self.target.with_name(f".{self.target.stem}.clothsr-check-{os.getpid()}.usda")
        layer = compose(self.top.tmp, self.input, Sdf.Layer.CreateNew(str(check)))
        layer.Save()
        try:
            base = {(i, m) for s, i, m in validate(str(self.input)) if s == "error"}
            issues = validate(str(check))
        finally:
            layer = None
            check.unlink(missing_ok=True)
        # A finding about the stage's root layer names the check file: say the shot instead.
        issues = [(s, i, m.replace(str(check), str(self.input))) for s, i, m in issues]
        errors = [(i, m) for s, i, m in issues if s == "error" and (i, m) not in base]
        if errors:
            text = "; ".join(f"{i}: {m}" for i, m in errors[:5])
            raise ValueError(f"{self.path}: the shot with this layer fails usd-core validation: {text}")
        return [f"{i}: {m}" for s, i, m in issues if s != "error"]

    def checkpoint(self):
        self._publish(False)

    def close(self) -> list:
        try:
            return self._publish(True)
        finally:
            for f in [self.top, self.static, self.manifest, *self.chunks.values()]:
                if f is not None:
                    f.drop()
            self.chunks = {}
