"""`flexreg config show NAME`: a command's configuration defaults as TOML, JSON or JSON schema;
`flexreg config docs`: every field's default, unit and meaning as Markdown.

``flexreg config show register > run.toml`` writes a starting file for ``--config run.toml``,
each key under its description; it reads back to exactly the defaults. The descriptions are
the configuration models' own (the Attributes of their docstrings), so the TOML comments, the
JSON schema and docs/configuration.md (``flexreg config docs --update``) say the same.
"""

from __future__ import annotations

import json
import re
from collections.abc import Callable
from pathlib import Path

import typer

from flexreg.calibration.config import CalibrationConfig
from flexreg.cli.app import app
from flexreg.config import Config, field_descriptions, to_toml, toml_text
from flexreg.errors import ConfigError
from flexreg.odometry.config import EvaluationConfig, OdometryConfig
from flexreg.registration.config import RegistrationConfig, leaf_fields
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
    "pick": CalibrationConfig,  # the picker's live solve is a calibration
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
        False,
        "--schema",
        help="Print the JSON schema (fields, descriptions, types, allowed values, ranges).",
    ),
) -> None:
    """Print the defaults of NAME's configuration (TOML unless --json or --schema), each field
    under a comment saying what it does and in which unit.

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


# ------------------------------------------------------------------------------ the reference

#: ``<!-- generated: NAME -->`` ... ``<!-- end generated: NAME -->``: a part of a Markdown
#: file :func:`update_docs` rewrites (``commands``: the table of configurations; ``fields``:
#: every field of each)
_REGION = re.compile(r"(<!-- generated: (\w+) -->\n)(.*?)(<!-- end generated: \2 -->)", re.S)
#: the command that rewrites docs/configuration.md (said where it is found out of date)
UPDATE_DOCS = "flexreg config docs --update docs/configuration.md"


def _models() -> dict[type[Config], tuple[list[str], Config]]:
    """Each configuration class, the commands that take it and its defaults."""
    out: dict[type[Config], tuple[list[str], Config]] = {}
    for command, defaults in CONFIGS.items():
        config = defaults()
        out.setdefault(type(config), ([], config))[0].append(command)
    return out


def _cell(text: str) -> str:
    return text.replace("|", "\\|")


def _module_path(cls: type) -> str:
    return cls.__module__.replace(".", "/") + ".py"


def _commands_table() -> list[str]:
    lines = ["| command | configuration | fields | module |", "|---|---|---|---|"]
    for cls, (commands, config) in _models().items():
        nested = [(k, v) for k, v in dict(config).items() if isinstance(v, Config)]
        own = len(cls.model_fields) - len(nested)
        count = f"{own}" + "".join(
            f" (+ {len(leaf_fields(type(v)))} in `[{k}]`)" for k, v in nested
        )
        names = ", ".join(f"`flexreg {c}`" for c in commands)
        lines.append(f"| {names} | `{cls.__name__}` | {count} | `{_module_path(cls)}` |")
    return lines


def _default(value: object) -> str:
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{k} = {toml_text(v)}" for k, v in value.items()) + " }"
    return toml_text(value)


def _fields_tables() -> list[str]:
    lines: list[str] = []
    models = _models()
    for cls, (commands, config) in models.items():
        names = ", ".join(f"`flexreg {c}`" for c in commands)
        lines += ["", f"### {names}: `{cls.__name__}`", ""]
        lines += ["| key | default | meaning [unit] |", "|---|---|---|"]
        notes = field_descriptions(cls)
        for key, value in config.model_dump(mode="json").items():
            note = notes.get(key, "")
            nested = getattr(config, key)
            if isinstance(nested, Config) and type(nested) in models:
                where = f"`flexreg {models[type(nested)][0][0]}`"
                lines.append(f"| `[{key}]` | a table | {_cell(note)}; its keys as for {where} |")
                continue
            lines += _rows(key, nested, value, note)
    return lines[1:]


def _rows(key: str, value: object, dumped: object, note: str) -> list[str]:
    """The table's rows of one field (``dumped``: its value as JSON); a table of its own
    (``[judge]``) as a row of its meaning and one row per key, written ``judge.KEY``."""
    if not isinstance(value, Config) or not isinstance(dumped, dict):
        return [f"| `{key}` | `{_cell(_default(dumped))}` | {_cell(note)} |"]
    lines = [f"| `[{key}]` | a table | {_cell(note)} |"]
    inner = field_descriptions(type(value))
    for name, v in dumped.items():
        lines += _rows(f"{key}.{name}", getattr(value, name), v, inner.get(name, ""))
    return lines


def render_docs(name: str) -> str:
    """The Markdown of one generated part of docs/configuration.md (``commands``,
    ``fields``)."""
    parts = {"commands": _commands_table, "fields": _fields_tables}
    if name not in parts:
        raise ConfigError(f"no generated part named {name!r}; known: {', '.join(parts)}")
    return "\n".join(parts[name]()) + "\n"


def update_docs(text: str) -> str:
    """``text`` with each generated part (between ``<!-- generated: NAME -->`` and
    ``<!-- end generated: NAME -->``) rendered again from the models."""
    return _REGION.sub(lambda m: m[1] + render_docs(m[2]) + m[4], text)


@config_app.command("docs")
def docs_command(
    update: Path | None = typer.Option(
        None,
        "--update",
        metavar="FILE",
        help="Rewrite the generated parts of this Markdown file (docs/configuration.md) in "
        "place instead of printing the reference.",
    ),
) -> None:
    """Print every configuration's fields with their defaults, units and meanings as Markdown
    (the reference of docs/configuration.md)."""
    if update is None:
        print(render_docs("commands") + "\n" + render_docs("fields"), end="")
        return
    try:
        text = update.read_text(encoding="utf-8")
    except OSError as e:
        raise ConfigError(f"--update: {update}: cannot be read: {e.strerror or e}") from None
    if not _REGION.search(text):
        raise ConfigError(f"--update: {update}: has no '<!-- generated: NAME -->' part")
    new = update_docs(text)
    if new != text:
        update.write_text(new, encoding="utf-8")
