"""The clothsr library's extension module; use the wrappers in ``clothsr``."""

from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

__version__: str

class ClothsrError(Exception):
    """A clothsr failure: bad input (naming the file and element), a failed simulation, I/O."""

class UsageError(ClothsrError):
    """The call asks for something that cannot be done (the command exits with 2)."""

class BadInputError(ClothsrError):
    """An input file is wrong; the message names the file and the element (exit code 3)."""

class RunError(ClothsrError):
    """The work failed while running (exit code 4)."""

class Cancelled(ClothsrError):
    """The progress callback stopped the work (it returned False)."""

def run(
    scene: str,
    output: str,
    models: str,
    *,
    frames: Optional[int] = ...,
    fabric: str = ...,
    avatar: Optional[str] = ...,
    colliders: Sequence[str] = ...,
    corrector: str = ...,
    restart: bool = ...,
    ascii: bool = ...,
    rrd: Optional[str] = ...,
    layer: str = ...,
    clip_frames: int = ...,
    publish_every_s: Optional[float] = ...,
    progress: Optional[Callable[[int, int], Optional[bool]]] = ...,
) -> Dict[str, Any]: ...
def convert(
    inputs: Sequence[str],
    output: str,
    *,
    colliders: Sequence[str] = ...,
    avatar: Optional[str] = ...,
    fabric: str = ...,
    fps: Optional[float] = ...,
    frames: Optional[int] = ...,
    ascii: bool = ...,
) -> List[str]: ...
def inspect(path: str, *, fabric: str = ...) -> Dict[str, Any]: ...
def eval(
    prediction: str, ground_truth: str, *, baselines: Sequence[Tuple[str, str]] = ...
) -> Dict[str, Dict[str, Any]]: ...
def fit(
    shot: str,
    output: str,
    *,
    generic_isr: Optional[str] = ...,
    quality: str = ...,
    fabric: str = ...,
    avatar: Optional[str] = ...,
    colliders: Sequence[str] = ...,
    frames: Optional[int] = ...,
    isr_steps: Optional[int] = ...,
    coarse_mm: Optional[float] = ...,
    fine_mm: Optional[float] = ...,
    progress: Optional[Callable[[int, int, str], Optional[bool]]] = ...,
) -> None: ...
def fit_plan(
    shot: str,
    output: str,
    *,
    generic_isr: Optional[str] = ...,
    quality: str = ...,
    fabric: str = ...,
    avatar: Optional[str] = ...,
    colliders: Sequence[str] = ...,
    frames: Optional[int] = ...,
    isr_steps: Optional[int] = ...,
    coarse_mm: Optional[float] = ...,
    fine_mm: Optional[float] = ...,
) -> List[Tuple[str, List[str]]]: ...
def fit_task(
    output: str,
    id: str,
    *,
    progress: Optional[Callable[[int, int, str], Optional[bool]]] = ...,
) -> None: ...
def shot_output(scene: str, out_dir: str) -> str: ...
def summarise(shots: str, error: Optional[str] = ...) -> str: ...
