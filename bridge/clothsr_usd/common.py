"""Units, axes and prim naming shared by the reader and the writer."""
import pathlib
import re

import numpy as np
from pxr import Tf, Usd, UsdGeom

# Z-up stage coordinates -> clothsr's y-up: (x, y, z) -> (x, z, -y).
Z_TO_Y = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])


# clothsr's schema version (clothsr_usd/schemas/schema.usda), written as the layer's customLayerData.
SCHEMA_VERSION = 1
SCHEMA_VERSION_KEY = "clothsr:schemaVersion"
# An override layer's customLayerData: the shot it is for, relative to the layer's folder.
LAYER_FOR_KEY = "clothsr:layerFor"
# The shot composed with an override layer, beside the layer: NAME.composed.usda.
COMPOSED_SUFFIX = ".composed.usda"
# Type names, newest first: schema version 0 had them unprefixed; both are read.
GARMENT_API = ("ClothsrGarmentAPI", "ClothGarmentAPI")
PANEL = ("ClothsrPanel", "ClothPanel")
SEAM = ("ClothsrSeam", "ClothSeam")
SOLVER_API = ("ClothsrSolverAPI", "ClothSolverAPI")


class BadInput(ValueError):
    """A file whose content clothsr cannot use; the message names the file and the element."""


def _check_dependencies(stage: Usd.Stage, path: str):
    """A sublayer, reference or payload that cannot be found is an error naming it (USD itself
    only warns and composes the stage without it)."""
    if hasattr(stage, "GetCompositionErrors"):
        missing = [
            str(e) for e in stage.GetCompositionErrors()
            if type(e).__name__ in ("ErrorInvalidAssetPath", "ErrorInvalidSublayerPath")
        ]
    else:  # USD before 24.11
        from pxr import UsdUtils

        missing = [
            f"cannot resolve @{p}@{_referenced_by(stage, p)}"
            for p in UsdUtils.ComputeAllDependencies(str(path))[2]
        ]
    if missing:
        more = f" (and {len(missing) - 1} more)" if len(missing) > 1 else ""
        raise BadInput(f"{path}: {missing[0]}{more}")


def _referenced_by(stage: Usd.Stage, asset: str) -> str:
    """" referenced by <prim>" for the first prim whose reference or payload names ``asset``."""
    import os

    name = os.path.basename(str(asset))
    for prim in stage.TraverseAll():
        for spec in prim.GetPrimStack():
            arcs = list(spec.referenceList.GetAddedOrExplicitItems())
            arcs += list(spec.payloadList.GetAddedOrExplicitItems())
            if any(os.path.basename(a.assetPath) == name for a in arcs if a.assetPath):
                return f" (referenced by {prim.GetPath()})"
    return ""


def compose(layer_path, shot_path, root=None, sublayers=None, over=None) -> "Sdf.Layer":
    """A root layer (``root``, else an anonymous one) holding the override layer at
    ``layer_path`` sublayered over the shot at ``shot_path``, with the layer's stage metadata.
    ``sublayers``: the two paths as written into the root (default: as given); ``over``: the
    override layer's content, where it is open and newer than its file."""
    from pxr import Sdf

    if over is None:
        over = Sdf.Layer.FindOrOpen(str(layer_path))
    if root is None:
        root = Sdf.Layer.CreateAnonymous("composed.usda")
    for path in sublayers or (layer_path, shot_path):
        root.subLayerPaths.append(str(path))
    for key in ("metersPerUnit", "upAxis", "timeCodesPerSecond", "framesPerSecond", "startTimeCode", "endTimeCode"):
        if over.pseudoRoot.HasInfo(key):
            root.pseudoRoot.SetInfo(key, over.pseudoRoot.GetInfo(key))
    root.customLayerData = dict(over.customLayerData)
    if over.defaultPrim:
        root.defaultPrim = over.defaultPrim
    return root


def composed_path(layer_path) -> pathlib.Path:
    """Where ``write_composed`` puts the shot composed with the override layer at
    ``layer_path``: ``NAME.composed.usda`` beside it."""
    p = pathlib.Path(layer_path)
    return p.with_name(f"{p.stem}{COMPOSED_SUFFIX}")


def write_composed(layer_path, shot_path, over=None) -> pathlib.Path:
    """Writes the shot with the override layer over it, to open or import as the shot with
    its fine cloth: a root layer whose sublayers are the layer (strongest) and the shot, both
    relative to it, with the layer's stage metadata. Every opinion of the shot, its root
    layer's own included, is weaker than the layer's, so a garment defined, referenced, under
    a payload or in a sublayer of the shot becomes the fine mesh. Published by rename; returns
    its path."""
    import os

    layer_path = pathlib.Path(layer_path).resolve()
    out = composed_path(layer_path)
    here = out.parent
    rel = [f"./{layer_path.name}", os.path.relpath(pathlib.Path(shot_path).resolve(), here)]
    if not rel[1].startswith("."):
        rel[1] = f"./{rel[1]}"
    tmp = out.with_name(f".{out.stem}.clothsr-pub-{os.getpid()}.usda")
    from pxr import Sdf

    layer = Sdf.Layer.CreateNew(str(tmp))
    compose(layer_path, shot_path, root=layer, sublayers=rel, over=over)
    data = dict(layer.customLayerData)
    data.pop(LAYER_FOR_KEY, None)
    layer.customLayerData = data
    layer.documentation = f"{rel[1]} with clothsr's fine cloth ({rel[0]}) over it"
    layer.Save()
    layer = None
    os.replace(tmp, out)
    return out


def open_stage(path: str) -> Usd.Stage:
    """The stage at ``path``; an override layer clothsr wrote, composed over its shot."""
    stage = _open(path)
    shot = stage.GetRootLayer().customLayerData.get(LAYER_FOR_KEY)
    if shot:
        shot_path = (pathlib.Path(stage.GetRootLayer().realPath).parent / shot).resolve()
        if not shot_path.exists():
            raise BadInput(f"{path}: an override layer for {shot_path}, which is missing")
        stage = Usd.Stage.Open(compose(stage.GetRootLayer().realPath, shot_path))
    return stage


def _open(path: str) -> Usd.Stage:
    try:
        stage = Usd.Stage.Open(str(path))
    except Exception as exc:  # Tf.ErrorException carries the parser's message
        msg = " ".join(str(exc).split())
        # Keep the parser's "file:line:col: what" part, not pxr's C++ locations.
        found = re.search(r"'[^']*?:(\d+):(\d+): (.*?)' in", msg)
        if found:
            msg = f"line {found.group(1)}, column {found.group(2)}: {found.group(3)}"
        raise BadInput(f"{path}: cannot open as USD: {msg[:300]}") from None
    if stage is None:
        raise BadInput(f"{path}: cannot open as USD")
    _check_dependencies(stage, path)
    version = stage.GetRootLayer().customLayerData.get(SCHEMA_VERSION_KEY, 0)
    if not isinstance(version, int) or version < 0:
        raise BadInput(f"{path}: customLayerData {SCHEMA_VERSION_KEY} = {version!r} is not a version")
    if version > SCHEMA_VERSION:
        raise BadInput(
            f"{path}: written with clothsr schema version {version}; this clothsr reads versions "
            f"up to {SCHEMA_VERSION} (update clothsr)"
        )
    return stage


#: The units taken for stages that do not author ``metersPerUnit`` (``None``: refused).
_assumed_meters_per_unit = None


def assume_meters_per_unit(value):
    """Takes ``value`` metres per unit for every stage read or layered over from now on that
    does not author ``metersPerUnit`` (``None``: such stages are refused). Returns the value
    it replaces."""
    global _assumed_meters_per_unit
    if value is not None:
        value = float(value)
        if not (np.isfinite(value) and value > 0):
            raise ValueError(f"meters per unit = {value}: expected a positive number")
    previous, _assumed_meters_per_unit = _assumed_meters_per_unit, value
    return previous


def units_assumed(stage: Usd.Stage):
    """The metres per unit taken for ``stage`` because it authors none, else ``None``."""
    if UsdGeom.StageHasAuthoredMetersPerUnit(stage):
        return None
    return _assumed_meters_per_unit


def stage_frame(stage: Usd.Stage, path: str):
    """(metersPerUnit, axis matrix to y-up) of a stage; unknown units are an error unless a
    value was given for them (:func:`assume_meters_per_unit`)."""
    if UsdGeom.StageHasAuthoredMetersPerUnit(stage):
        mpu = float(UsdGeom.GetStageMetersPerUnit(stage))
    elif _assumed_meters_per_unit is not None:
        mpu = _assumed_meters_per_unit
    else:
        raise BadInput(
            f"{path}: metersPerUnit is not authored, so the units are unknown (author it in "
            "the stage metadata, e.g. metersPerUnit = 1, or give them: --meters-per-unit M, "
            "meters_per_unit=M in Python)"
        )
    if not (np.isfinite(mpu) and mpu > 0):
        raise BadInput(f"{path}: metersPerUnit = {mpu} is not a positive number")
    up = UsdGeom.GetStageUpAxis(stage)
    axes = Z_TO_Y if up == UsdGeom.Tokens.z else np.eye(3)
    return mpu, axes


def valid_name(name: str) -> str:
    return Tf.MakeValidIdentifier(str(name)) or "unnamed"
