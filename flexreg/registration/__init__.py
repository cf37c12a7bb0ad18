"""Pairwise registration of scans: :func:`register` (one pair), :class:`Registration`
(``prepare`` each scan once, ``align`` many pairs), :class:`RegistrationConfig`,
:class:`RegistrationResult` and its verdict (:func:`decide`, :mod:`.verdict`)."""

from flexreg.registration.config import RegistrationConfig
from flexreg.registration.pipeline import PreparedScan, Registration, register
from flexreg.registration.result import RegistrationResult
from flexreg.registration.verdict import decide

__all__ = [
    "PreparedScan",
    "Registration",
    "RegistrationConfig",
    "RegistrationResult",
    "decide",
    "register",
]
