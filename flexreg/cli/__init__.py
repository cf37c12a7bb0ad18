"""``flexreg`` command line: a thin adapter over the library.

Each command lives in its own module and registers itself on :data:`flexreg.cli.app.app`;
heavy imports happen inside the commands (``flexreg --help`` stays fast). Known errors become
one line ``error: <file>: <problem>`` and exit status 1.
"""

from __future__ import annotations

from flexreg.cli import (  # noqa: F401  (each module registers its commands on `app`)
    calibrate,
    compare,
    config_cmd,
    convert,
    evaluate,
    odometry,
    pick,
    register,
    scan_commands,
    survey,
    synth,
)
from flexreg.cli.app import app, main, run

__all__ = ["app", "main", "run"]
