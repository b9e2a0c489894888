"""``saucerfab verify``: see the print before printing it.

Ray-traces the *exported files* of a print folder (read back from disk)
with Mitsuba 3, the cup as a perfect mirror from ``scene.json``, from the
design eye, a viewer's two eyes or an eye box, and scores each view against
the input pictures as the designer meant them (PSNR, SSIM, coverage). See
:mod:`saucerfab.verify.core` for the rules and ``saucerfab/verify/README.md``
for the JSON schema.
"""

from saucerfab.model.eyes import EyeSpec, parse_eyes
from saucerfab.verify.core import (
    DEFAULT_MIN_COVERAGE,
    DEFAULT_MIN_PSNR_DB,
    DEFAULT_RES,
    DEFAULT_SPP,
    stand_sentence,
    verify_print,
)
from saucerfab.verify.printfolder import VerifyInputError, reference_name
from saucerfab.verify.results import SCHEMA, FileScore, VerifyResult, ViewScore

__all__ = [
    "DEFAULT_MIN_COVERAGE",
    "DEFAULT_MIN_PSNR_DB",
    "DEFAULT_RES",
    "DEFAULT_SPP",
    "SCHEMA",
    "EyeSpec",
    "FileScore",
    "VerifyInputError",
    "VerifyResult",
    "ViewScore",
    "parse_eyes",
    "reference_name",
    "stand_sentence",
    "verify_print",
]
