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
        "usd-core (the 'pxr' module) is not installed in this Python environment: "
        "run `bash .ci/setup` in the clothsr repository (it creates .venv with "
        "usd-core==26.11 and numpy)"
    ) from exc

from .common import PANEL, SCHEMA_VERSION  # noqa: E402
from .plot import plot_errors  # noqa: E402
from .read import inspect_stage, read_stage  # noqa: E402
from .validate import validate  # noqa: E402
from .write import AnimationWriter, write_stage  # noqa: E402
from .layer import LayerWriter  # noqa: E402

__all__ = ["SCHEMA_VERSION", "plot_errors", "inspect_stage", "read_stage", "validate", "write_stage", "AnimationWriter", "LayerWriter", "schema_registered"]


def schema_registered() -> bool:
    """True when clothsr's schema types are known to USD."""
    from pxr import Usd as _Usd

    reg = _Usd.SchemaRegistry()
    return reg.FindConcretePrimDefinition(PANEL[0]) is not None
