"""Runs every validator registered with usd-core (``UsdValidation``) on a file; where the host's
USD predates ``UsdValidation`` (before 24.11), the older ``UsdUtils.ComplianceChecker``."""
from pxr import Usd, UsdShade

try:
    from pxr import UsdValidation
except ImportError:  # USD before 24.11
    UsdValidation = None


def validate(path: str) -> list:
    """Returns ``[(severity, identifier, message), ...]`` for every issue usd-core finds.

    ``severity`` is ``"error"``, ``"warning"`` or ``"info"``.
    """
    if UsdValidation is None:
        return _compliance(path)
    stage = Usd.Stage.Open(path)
    _register_connectable_behaviors(stage)
    registry = UsdValidation.ValidationRegistry()
    ctx = UsdValidation.ValidationContext(registry.GetOrLoadAllValidators())
    out = []
    for err in ctx.Validate(stage):
        if err.HasNoError():
            continue
        t = err.GetType()
        sev = {
            UsdValidation.ValidationErrorType.Error: "error",
            UsdValidation.ValidationErrorType.Warn: "warning",
        }.get(t, "info")
        validator = err.GetValidator()
        ident = str(validator.GetMetadata().name) if validator else str(err.GetName())
        out.append((sev, ident, err.GetErrorAsString()))
    return out


def _register_connectable_behaviors(stage) -> None:
    """Looks up every prim's UsdShade connectable behaviour on this thread first.

    Validators run on USD's worker threads, and some USD builds (Blender's 25.08) register a
    prim type's behaviour lazily without a lock: two workers meeting the same new type raise
    "Connectable behavior already registered". Once registered, lookups only read."""
    predicate = Usd.TraverseInstanceProxies(Usd.PrimAllPrimsPredicate)
    for prim in Usd.PrimRange.Stage(stage, predicate):
        UsdShade.ConnectableAPI(prim).IsContainer()


def _compliance(path: str) -> list:
    from pxr import UsdUtils

    checker = UsdUtils.ComplianceChecker()
    checker.CheckCompliance(str(path))
    ident = "UsdUtils.ComplianceChecker"
    out = [("error", ident, str(m)) for m in checker.GetErrors()]
    out += [("error", ident, str(m)) for m in checker.GetFailedChecks()]
    out += [("warning", ident, str(m)) for m in checker.GetWarnings()]
    return out
