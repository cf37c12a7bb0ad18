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

#: said under every command's options (they are root options, accepted in either place)
_ROOT_FLAGS = (
    "An --out (or other output) that exists is refused unless --overwrite is given; "
    "--overwrite and -v / --verbose may be given before or after the command "
    "(flexreg --help)."
)
for _info in app.registered_commands:
    if _info.epilog is None:
        _info.epilog = _ROOT_FLAGS

__all__ = ["app", "main", "run"]
