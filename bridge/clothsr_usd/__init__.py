"""clothsr's USD bridge: reads and writes USD stages for the clothsr library (the binary, and
the ``clothsr`` Python package in a DCC's own Python, with its ``pxr``).

Arrays cross as whole numpy buffers; no pxr object leaves this package. Importing it registers
clothsr's codeless schema (``schemas/`` beside this file, or ``CLOTHSR_SCHEMAS``) with ``Plug.Registry`` before
``Usd`` loads. The process environment is never written: a ``setenv`` while another thread of the
host spawns a process can hand that process a freed environment (seen as EFAULT from exec).
"""
import os
import pathlib

_SCHEMAS = os.environ.get("CLOTHSR_SCHEMAS") or str(pathlib.Path(__file__).resolve().parent / "schemas")

try:
    from pxr import Plug

    Plug.Registry().RegisterPlugins(_SCHEMAS)
    from pxr import Usd  # noqa: F401
except ImportError as exc:  # pragma: no cover - the message is the point
    raise ImportError(
        "clothsr reads and writes USD through the host's own USD Python modules ('pxr'), and "
        "this Python has none: run clothsr inside a DCC's Python (Houdini, Maya, Omniverse, "
        "Blender), or install them with `pip install 'clothsr[usd]'` (usd-core)"
    ) from exc

from .common import PANEL, SCHEMA_VERSION, assume_meters_per_unit, composed_path, write_composed  # noqa: E402
from .plot import plot_errors  # noqa: E402
from .read import inspect_stage, read_stage  # noqa: E402
from .validate import validate  # noqa: E402
from .write import AnimationWriter, write_stage  # noqa: E402
from .layer import LayerWriter  # noqa: E402

__all__ = ["SCHEMA_VERSION", "assume_meters_per_unit", "composed_path", "write_composed", "plot_errors", "inspect_stage", "read_stage", "validate", "write_stage", "AnimationWriter", "LayerWriter", "schema_registered"]


def schema_registered() -> bool:
    """True when clothsr's schema types are known to USD."""
    from pxr import Usd as _Usd

    reg = _Usd.SchemaRegistry()
    return reg.FindConcretePrimDefinition(PANEL[0]) is not None
