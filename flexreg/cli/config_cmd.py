"""`flexreg config show NAME`: a command's configuration defaults as TOML, JSON or JSON schema.

``flexreg config show register > run.toml`` writes a starting file for ``--config run.toml``;
it reads back to exactly the defaults.
"""

from __future__ import annotations

import json
from collections.abc import Callable

import typer

from flexreg.calibration.config import CalibrationConfig
from flexreg.cli.app import app
from flexreg.config import Config, to_toml
from flexreg.errors import ConfigError
from flexreg.odometry.config import EvaluationConfig, OdometryConfig
from flexreg.registration.config import RegistrationConfig
from flexreg.synth.config import SynthConfig


def _bench_defaults() -> Config:
    """The bench's full-suite defaults (its module loads the benchmark machinery: imported
    only when asked for, so that every other command starts fast)."""
    from flexreg.bench.types import BenchConfig

    return BenchConfig.make()


#: command -> its default configuration (the one --config and --set start from)
CONFIGS: dict[str, Callable[..., Config]] = {
    "register": RegistrationConfig,
    "calibrate": CalibrationConfig,
    "odometry": OdometryConfig,
    "evaluate": EvaluationConfig,
    "synth": SynthConfig,
    "bench": _bench_defaults,
}

config_app = typer.Typer(
    help="Configurations of the commands: defaults, file format, fields.",
    no_args_is_help=True,
    rich_markup_mode=None,
)
app.add_typer(config_app, name="config")


def add_config(command: str, defaults: Callable[[], Config]) -> None:
    """Make a command's configuration known to ``flexreg config show COMMAND`` (for commands
    whose configuration lives beside the command); ``defaults()`` gives its defaults."""
    CONFIGS[command] = defaults


@config_app.command("show")
def show_command(
    name: str = typer.Argument(
        ..., metavar="NAME", help="Command: register, calibrate, odometry, evaluate, compare, ..."
    ),
    as_json: bool = typer.Option(False, "--json", help="Print JSON instead of TOML."),
    as_toml: bool = typer.Option(False, "--toml", help="Print TOML (the default)."),
    schema: bool = typer.Option(
        False, "--schema", help="Print the JSON schema (fields, types, allowed values, ranges)."
    ),
) -> None:
    """Print the defaults of NAME's configuration (TOML unless --json or --schema).

    Save it, edit it, and pass it back with --config FILE; --set KEY=VALUE changes single
    fields on the command line.
    """
    defaults = CONFIGS.get(name)
    if defaults is None:
        raise ConfigError(f"NAME: unknown command {name!r}; known: {', '.join(CONFIGS)}")
    config = defaults()
    if as_json + as_toml + schema > 1:
        raise ConfigError("--toml, --json, --schema: give at most one")
    if schema:
        print(json.dumps(type(config).model_json_schema(), indent=2))
    elif as_json:
        print(json.dumps(config.to_dict(), indent=2))
    else:
        header = (
            f"flexreg {name}: default configuration ({type(config).__name__}).\n"
            f"Use with: flexreg {name} ... --config FILE [--set KEY=VALUE ...]"
        )
        print(to_toml(config, header=header), end="")
