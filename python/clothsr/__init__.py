"""clothsr: super-resolution cloth animation, in-process.

The clothsr library (Rust) loaded into this Python: a coarse cloth simulation lifted to a fine,
wrinkled mesh by learned networks (Yu & Wang, SIGGRAPH 2024), written as time-sampled USD.
USD goes through this interpreter's own ``pxr`` (a DCC's, or ``pip install clothsr[usd]``).
The GIL is free while clothsr works, so a host's other threads keep running.

    import clothsr
    layer = clothsr.run("shot.usda", "shot_cloth.usdc", progress=lambda done, total: print(done, total))
    # shot_cloth.composed.usda beside it is the shot with its fine cloth; for an open stage:
    clothsr.compose(stage, layer)

Every function takes file paths; ``run``, ``inspect`` and ``fit`` also take an open
``Usd.Stage`` (its composed state, unsaved edits included). Errors raise a ``ClothsrError``
of their kind: ``UsageError`` (the call), ``BadInputError`` (a file, named with the element at
fault), ``RunError`` (a failure while running); a progress callback returning ``False`` raises
``Cancelled``.
"""

from __future__ import annotations

import contextlib
import math
import os
import pathlib
import tempfile
from typing import TYPE_CHECKING, Any, Callable, Dict, Iterator, List, Literal, Optional, Sequence, Tuple, Union

from . import _clothsr
from ._clothsr import BadInputError, Cancelled, ClothsrError, RunError, UsageError, __version__

try:
    # Registers clothsr's USD schema now, before this process opens a stage if it has not
    # yet (the bridge also reads and writes without it: a DCC has USD loaded long before).
    import clothsr_usd as _bridge  # noqa: F401
except ImportError:  # no `pxr` here: the USD calls say so when they are made
    pass

__all__ = [
    "BadInputError",
    "Cancelled",
    "ClothsrError",
    "RunError",
    "UsageError",
    "__version__",
    "compose",
    "convert",
    "evaluate",
    "fit",
    "generic_models",
    "inspect",
    "run",
]

if TYPE_CHECKING:
    from pxr import Sdf, Usd  # noqa: F401

PathLike = Union[str, "os.PathLike[str]"]
#: A fabric preset, for garments that name none.
Fabric = Literal["silk", "cotton", "denim", "leather"]
#: Whether a run uses the models folder's corrector: as its ``models.json`` says, or forced.
CorrectorChoice = Literal["auto", "on", "off"]
#: What a run writes: an override layer for a USD shot (``"auto"`` for USD input, or ``"on"``),
#: or a standalone stage (``"off"``); ``True``/``False``/``None`` as ``"on"``/``"off"``/``"auto"``.
LayerChoice = Union[Literal["auto", "on", "off"], bool, None]
Quality = Literal["preview", "final"]
#: ``progress(done, total)``; returning ``False`` stops the work.
Progress = Callable[[int, int], Optional[bool]]


def generic_models() -> pathlib.Path:
    """The models ``run`` uses by default: ``$CLOTHSR_MODELS``, else the generic models shipped
    in this package (trained on procedural shots, validated on held-out garments, colliders,
    motions and fabrics; see their ``README.md``)."""
    env = os.environ.get("CLOTHSR_MODELS")
    if env:
        return pathlib.Path(env)
    return pathlib.Path(__file__).resolve().parent / "models" / "generic"


def _is_stage(x: Any) -> bool:
    return type(x).__name__ == "Stage" and hasattr(x, "GetRootLayer")


def _name_the_shot(layer: "Sdf.Layer", scene: Any) -> None:
    """An override layer made from an exported ``Usd.Stage`` names the stage's own root layer
    as its shot (none for an in-memory stage), not the temporary export; so does the composed
    shot beside it (none for an in-memory stage)."""
    key = "clothsr:layerFor"
    if not _is_stage(scene) or key not in layer.customLayerData:
        return
    root = scene.GetRootLayer()
    data = dict(layer.customLayerData)
    saved = not root.anonymous and bool(root.realPath)
    if saved:
        base = pathlib.Path(layer.realPath).parent if layer.realPath else pathlib.Path.cwd()
        data[key] = os.path.relpath(root.realPath, base)
    else:
        del data[key]
    layer.customLayerData = data
    if layer.anonymous:
        return
    layer.Save()
    import clothsr_usd

    if saved:
        clothsr_usd.write_composed(layer.realPath, root.realPath, over=layer)
    else:
        clothsr_usd.composed_path(layer.realPath).unlink(missing_ok=True)


def compose(stage: Any, layer: Any) -> None:
    """Applies a run's override layer to the open ``Usd.Stage`` of its shot, as the composed
    shot ``NAME.composed.usda`` written beside the layer does for files: the layer (an
    ``Sdf.Layer`` or a path) goes first among the sublayers of the stage's session layer, so
    its opinions are stronger than every layer of the shot, the root layer's own included.
    Each garment then reads as its fine animated mesh at its own prim path, wherever the shot
    defines it. Nothing of the shot's own layers changes and nothing is saved; composing the
    same layer again moves it back to the front."""
    if not _is_stage(stage):
        raise UsageError(f"compose: expected an open Usd.Stage, got {type(stage).__name__}")
    identifier = layer if isinstance(layer, (str, os.PathLike)) else layer.identifier
    identifier = os.fspath(identifier)
    session = stage.GetSessionLayer()
    paths = [p for p in session.subLayerPaths if p != identifier]
    session.subLayerPaths = [identifier, *paths]


@contextlib.contextmanager
def _scene_path(scene: Any) -> Iterator[pathlib.Path]:
    """A file for ``scene``: a path as given; a ``Usd.Stage`` read from its root layer's file
    when that is saved and unedited, else exported (flattened) to a temporary file."""
    if not _is_stage(scene):
        yield pathlib.Path(os.fspath(scene))
        return
    root = scene.GetRootLayer()
    edited = any(layer.dirty for layer in scene.GetUsedLayers())
    if not root.anonymous and not edited and root.realPath:
        yield pathlib.Path(root.realPath)
        return
    with tempfile.TemporaryDirectory(prefix="clothsr-") as tmp:
        path = pathlib.Path(tmp) / "stage.usdc"
        if not scene.Export(str(path)):
            raise ClothsrError(f"cannot export the stage {root.identifier} to {path}")
        yield path


@contextlib.contextmanager
def _units(meters_per_unit: Optional[float]) -> Iterator[None]:
    """USD files that state no units (no ``metersPerUnit``) read in ``meters_per_unit`` for
    the call (``None``: such files are refused)."""
    if meters_per_unit is None:
        yield
        return
    if isinstance(meters_per_unit, bool) or not isinstance(meters_per_unit, (int, float)) or not (
        math.isfinite(meters_per_unit) and meters_per_unit > 0
    ):
        raise UsageError(f"meters_per_unit={meters_per_unit!r}: expected a positive number (0.01: centimetres)")
    import clothsr_usd

    previous = clothsr_usd.assume_meters_per_unit(float(meters_per_unit))
    try:
        yield
    finally:
        clothsr_usd.assume_meters_per_unit(previous)


def _open_layer(path: pathlib.Path, keep: bool) -> "Sdf.Layer":
    """The USD layer at ``path``: reloaded where this interpreter has it open already; when
    the file is temporary (``keep`` False), an anonymous copy."""
    from pxr import Sdf

    if not keep:
        layer = Sdf.Layer.CreateAnonymous(path.suffix)
        layer.TransferContent(Sdf.Layer.OpenAsAnonymous(str(path)))
        return layer
    layer = Sdf.Layer.Find(str(path))
    if layer is not None:
        layer.Reload(True)
        return layer
    return Sdf.Layer.FindOrOpen(str(path))


@contextlib.contextmanager
def _output(output: Optional[PathLike]) -> Iterator[Tuple[pathlib.Path, bool]]:
    if output is not None:
        yield pathlib.Path(os.fspath(output)), True
        return
    with tempfile.TemporaryDirectory(prefix="clothsr-") as tmp:
        yield pathlib.Path(tmp) / "out.usdc", False


def _path(x: Optional[PathLike]) -> Optional[str]:
    return os.fspath(x) if x is not None else None


def _paths(xs: Sequence[PathLike]) -> List[str]:
    return [os.fspath(x) for x in xs]


def _layer_word(layer: LayerChoice) -> str:
    words = {None: "auto", True: "on", False: "off", "auto": "auto", "on": "on", "off": "off"}
    if isinstance(layer, (bool, str, type(None))) and layer in words:
        return words[layer]
    raise UsageError(f"layer={layer!r}: expected 'auto', 'on' or 'off' (or None, True, False)")


def run(
    scene: Any,
    output: Optional[PathLike] = None,
    *,
    models: Optional[PathLike] = None,
    frames: Optional[int] = None,
    fabric: Fabric = "cotton",
    avatar: Optional[PathLike] = None,
    colliders: Sequence[PathLike] = (),
    corrector: CorrectorChoice = "auto",
    restart: bool = False,
    ascii: bool = False,
    rrd: Optional[PathLike] = None,
    layer: LayerChoice = None,
    clip_frames: int = 100,
    publish_every_s: Optional[float] = None,
    meters_per_unit: Optional[float] = None,
    progress: Optional[Progress] = None,
) -> "Sdf.Layer":
    """Runs the whole pipeline on a shot and returns the output layer (``Sdf.Layer``).

    ``scene``: a USD, GarmentCode JSON or OBJ file, or an open ``Usd.Stage``. ``output``: the
    USD file to write (fine garments as time-sampled points); ``None`` writes an anonymous
    layer. ``models``: a models folder (default :func:`generic_models`). ``frames``: how many
    (default: the scene's range). ``fabric``: the preset for garments without one;
    ``avatar``/``colliders``: extra collider files. ``corrector``: ``auto``, ``on`` or
    ``off``. An interrupted run of the same settings resumes from its last published frame
    unless ``restart``. ``rrd``: also save a Rerun recording. ``layer``: ``"on"`` writes an
    override layer for the USD shot (the default for USD input: each garment becomes its fine
    animated mesh at its own prim, in the shot's units, axis and time codes; apply it to an
    open stage with :func:`compose`, or open ``NAME.composed.usda`` written beside it), ``"off"`` a standalone stage (garments under ``/World/Garments``, colliders,
    metres, y up); a layered shot longer than ``clip_frames`` frames goes to value clips.
    ``publish_every_s``: seconds between publishing the files and the resume point while
    running (default 10; 0: every frame). ``meters_per_unit``: the units of USD files that
    state none (no ``metersPerUnit``; 0.01 for centimetres), which are refused without it.
    ``progress(done, total)`` is
    called after every frame, with the GIL taken; returning ``False`` stops the run (raising
    :class:`Cancelled`; the file keeps the frames so far and the next call resumes), and an
    exception it raises stops the run and propagates.
    """
    with _units(meters_per_unit), _scene_path(scene) as path, _output(output) as (out, keep):
        _clothsr.run(
            os.fspath(path),
            os.fspath(out),
            _path(models) or os.fspath(generic_models()),
            frames=frames,
            fabric=fabric,
            avatar=_path(avatar),
            colliders=_paths(colliders),
            corrector=corrector,
            restart=restart,
            ascii=ascii,
            rrd=_path(rrd),
            layer=_layer_word(layer),
            clip_frames=clip_frames,
            publish_every_s=publish_every_s,
            progress=progress,
        )
        result = _open_layer(out, keep)
        _name_the_shot(result, scene)
        return result


def convert(
    inputs: Union[PathLike, Sequence[PathLike]],
    output: Optional[PathLike] = None,
    *,
    avatar: Optional[PathLike] = None,
    colliders: Sequence[PathLike] = (),
    fabric: Fabric = "cotton",
    fps: Optional[float] = None,
    frames: Optional[int] = None,
    ascii: bool = False,
    meters_per_unit: Optional[float] = None,
) -> "Sdf.Layer":
    """Makes a USD scene with clothsr's schema from garments (GarmentCode JSON, OBJ, USD;
    several go onto one avatar) and colliders; returns its layer (``Sdf.Layer``). ``output``
    ``None`` returns an anonymous layer. ``meters_per_unit``: as for :func:`run`."""
    if isinstance(inputs, (str, os.PathLike)):
        inputs = [inputs]
    with _units(meters_per_unit), _output(output) as (out, keep):
        if not keep:
            out = out.with_suffix(".usda")
        _clothsr.convert(
            _paths(inputs),
            os.fspath(out),
            colliders=_paths(colliders),
            avatar=_path(avatar),
            fabric=fabric,
            fps=fps,
            frames=frames,
            ascii=ascii,
        )
        return _open_layer(out, keep)


def inspect(
    scene: Any, *, fabric: Fabric = "cotton", meters_per_unit: Optional[float] = None
) -> Dict[str, Any]:
    """What a garment, mesh or scene file (or an open ``Usd.Stage``) holds: garments (panels,
    seams, area, fabric), cloth meshes (vertices, triangles), colliders (frames), frame rate
    and range, as a dict. ``meters_per_unit``: as for :func:`run`."""
    with _units(meters_per_unit), _scene_path(scene) as path:
        return _clothsr.inspect(os.fspath(path), fabric=fabric)


def evaluate(
    prediction: PathLike,
    ground_truth: PathLike,
    *,
    baselines: Optional[Dict[str, PathLike]] = None,
) -> Dict[str, Dict[str, Any]]:
    """Errors of a run's fine meshes (and of ``baselines``, by name) against a fine simulation
    of the same shot (USD, or a ``clothsr lab dataset`` folder), per series: ``frames``,
    ``mean_mm``, ``max_mm``, ``std_mm``, ``normal_deg``, ``jitter_mm`` and
    ``per_frame_mean_mm`` as (time code, mm) pairs."""
    return _clothsr.eval(
        os.fspath(prediction),
        os.fspath(ground_truth),
        baselines=[(k, os.fspath(v)) for k, v in (baselines or {}).items()],
    )


def fit(
    shot: Any,
    output: PathLike,
    *,
    quality: Quality = "preview",
    fabric: Fabric = "cotton",
    avatar: Optional[PathLike] = None,
    colliders: Sequence[PathLike] = (),
    frames: Optional[int] = None,
    isr_steps: Optional[int] = None,
    from_scratch: bool = False,
    coarse_mm: Optional[float] = None,
    fine_mm: Optional[float] = None,
    meters_per_unit: Optional[float] = None,
    progress: Optional[Callable[[int, int, str], Optional[bool]]] = None,
) -> pathlib.Path:
    """Makes the best models for one shot in the folder ``output`` (variations simulated, the
    coarse model calibrated, the ISR network fine-tuned from the generic one unless
    ``from_scratch``, a held-out report); a fit stopped there resumes. ``quality``:
    ``preview`` or ``final``. ``coarse_mm``/``fine_mm``: the resolutions (default 20 and
    2.5). ``meters_per_unit``: as for :func:`run`. ``progress(done, total, message)`` sees
    each task. Returns the folder, for
    ``run(..., models=...)``. :func:`clothsr.batch.fit` runs the same fit's tasks on Ray."""
    generic_isr = None if from_scratch else os.fspath(generic_models() / "isr")
    with _units(meters_per_unit), _scene_path(shot) as path:
        _clothsr.fit(
            os.fspath(path),
            os.fspath(output),
            generic_isr=generic_isr,
            quality=quality,
            fabric=fabric,
            avatar=_path(avatar),
            colliders=_paths(colliders),
            frames=frames,
            isr_steps=isr_steps,
            coarse_mm=coarse_mm,
            fine_mm=fine_mm,
            progress=progress,
        )
    return pathlib.Path(os.fspath(output))
