"""The checks usdchecker runs, on a written layer.

usd-core 26 has no `UsdUtils.ComplianceChecker` any more: OpenUSD replaced it, and the rules
`usdchecker` applies, with the validation framework (`pxr.UsdValidation`, OpenUSD proposal
"USD Validation Framework"). `validate_usd` runs every validator registered in this build except
those for usdz packages (our layers are not packages) and returns the errors, as usdchecker
reports them; warnings are logged. docs/export.md also records the result of the older
ComplianceChecker (usd-core 25.5) on the demo exports. pyproject asks for usd-core 26.11: 24.11
has no UsdValidation, and 25.5's wheel has it without its validator plugins (they fail to load).
"""

from __future__ import annotations

import logging
from pathlib import Path

from pxr import Usd, UsdValidation

__all__ = ["validate_usd", "validators"]

log = logging.getLogger(__name__)

PACKAGE_ONLY = "UsdzValidators"


def validators() -> list:
    """The registered validators that apply to a plain (not usdz) layer."""
    registry = UsdValidation.ValidationRegistry()
    return [v for v in registry.GetOrLoadAllValidators() if PACKAGE_ONLY not in v.GetMetadata().GetKeywords()]


def validate_usd(path) -> list[str]:
    """Errors of the validators on the stage at `path` ("<validator>: <message>"), [] if none."""
    stage = Usd.Stage.Open(str(Path(path)))
    errors = []
    for error in UsdValidation.ValidationContext(validators()).Validate(stage):
        text = f"{error.GetValidator().GetMetadata().name}: {error.GetMessage()}"
        if error.GetType() == UsdValidation.ValidationErrorType.Error:
            errors.append(text)
        elif not error.HasNoError():
            log.warning("%s: %s", path, text)
    return errors
