"""Exception hierarchy: one root, :class:`FlexregError`, and a subclass per kind of failure.

The library raises these and never prints or exits; the CLI turns them into one line
(``error: <message>``) and exit status 1.
"""

from __future__ import annotations

from os import PathLike


class FlexregError(Exception):
    """Root of every error flexreg raises on purpose."""


class InputError(FlexregError, ValueError):
    """A file or argument that cannot be used as given.

    Parameters
    ----------
    source : str or path-like or None
        The file (or argument name) at fault; it leads the message.
    problem : str
        What is wrong with it, in one line.
    """

    def __init__(self, source: str | PathLike[str] | None, problem: str) -> None:
        self.source = None if source is None else str(source)
        self.problem = problem
        super().__init__(problem if source is None else f"{source}: {problem}")


class DegenerateGeometryError(FlexregError, ValueError):
    """Geometry that does not determine the requested quantity (too few or collinear points)."""


class RegistrationError(FlexregError):
    """Registration could not produce a trustworthy transform."""


class CalibrationError(RegistrationError):
    """The 2D-3D correspondences do not determine a trustworthy camera-lidar extrinsic."""


class ClusterError(FlexregError):
    """The local Dask cluster did not start (a full or unwritable disk for its workers'
    directories, a port or process limit)."""


class ConfigError(FlexregError, ValueError):
    """An invalid option or configuration value."""


class MemoryBudgetError(InputError):
    """Data a file or option declares would not fit the memory budget
    (:mod:`flexreg.core.budget`); raised before anything is allocated."""
