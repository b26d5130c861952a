"""Runs every validator registered with usd-core (``UsdValidation``) on a file."""
from pxr import Usd, UsdValidation


def validate(path: str) -> list:
    """Returns ``[(severity, identifier, message), ...]`` for every issue usd-core finds.

    ``severity`` is ``"error"``, ``"warning"`` or ``"info"``.
    """
    stage = Usd.Stage.Open(path)
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
