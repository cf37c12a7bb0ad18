"""Pairwise registration of scans: :func:`register` (one pair), :class:`Registration`
(``prepare`` each scan once, ``align`` many pairs), :class:`RegistrationConfig`,
:class:`RegistrationResult` and its verdict (:func:`decide`, :mod:`.verdict`, on the evidence of
:mod:`.evidence`)."""

from flexreg.exports import lazy

#: public name -> the module that defines it (loaded on first use: see flexreg.exports)
_WHERE = {
    "PreparedScan": "flexreg.registration.pipeline",
    "Registration": "flexreg.registration.pipeline",
    "RegistrationConfig": "flexreg.registration.config",
    "RegistrationResult": "flexreg.registration.result",
    "decide": "flexreg.registration.verdict",
    "register": "flexreg.registration.pipeline",
}
__getattr__, __dir__ = lazy(globals(), _WHERE)
__all__ = list(_WHERE)
