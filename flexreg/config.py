"""Validated configurations: one model per application, loadable from TOML or JSON.

Every application (registration, calibration, odometry, synthetic data, benchmarks, later the
survey) has one :class:`Config` subclass holding all its knobs with their defaults, units (in
the field names or docs) and allowed ranges. Rules live on the fields (pydantic constraints or
one validator per rule), so a bad value is refused in one place, with the field's name:

>>> from pydantic import Field
>>> class Demo(Config):
...     n: int = Field(5, ge=3)
...     label: str | None = None
>>> Demo(n=7).n
7
>>> Demo(n=1)
Traceback (most recent call last):
...
flexreg.errors.ConfigError: n: Input should be greater than or equal to 3 (got 1)
>>> load_config(Demo, overrides=parse_sets(["n=9", "label=none"]))
Demo(n=9, label=None)
>>> print(to_toml(Demo()), end="")
n = 5
# label = none

A run stores its effective configuration (``config.to_dict()``) in its result JSON;
:func:`load_config` reads that JSON (its ``"config"`` key) as readily as a TOML file, so feeding
it back reproduces the run bit for bit.

The library is pydantic v2 (``BaseModel``, frozen, unknown keys refused): kiss-icp, a dependency,
already requires it; its field constraints give one place per rule and error messages that name
the field; models pickle (Dask) and export a JSON schema (the picker's form).
"""

from __future__ import annotations

import json
import math
import sys
import types
import typing
from collections.abc import Iterable, Mapping
from os import PathLike
from pathlib import Path
from typing import Any, TypeVar

from pydantic import BaseModel, ConfigDict, ValidationError, model_validator

from flexreg.errors import ConfigError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

__all__ = ["Config", "load_config", "parse_sets", "to_toml"]

C = TypeVar("C", bound="Config")

#: Written (and accepted) for "no value": TOML has no null.
NONE_WORDS = ("none", "null")


def _allows_none(annotation: Any) -> bool:
    if annotation is None or annotation is type(None):
        return True
    origin = typing.get_origin(annotation)
    if origin in (typing.Union, types.UnionType):
        return any(_allows_none(a) for a in typing.get_args(annotation))
    if origin is typing.Annotated:
        return _allows_none(typing.get_args(annotation)[0])
    return False


def _one_line(e: ValidationError, where: str | None = None) -> str:
    """The first problem of a pydantic error as ``[where: ]field: message (got value)``."""
    err = e.errors(include_url=False)[0]
    field = ".".join(str(p) for p in err.get("loc", ())) or "value"
    msg = str(err.get("msg", "invalid value"))
    msg = msg.removeprefix("Value error, ")
    got = err.get("input")
    text = f"{field}: {msg}"
    if err.get("type") not in ("missing", "extra_forbidden") and not isinstance(got, dict):
        text += f" (got {got!r})"
    if len(e.errors()) > 1:
        text += f"; and {len(e.errors()) - 1} more"
    return f"{where}: {text}" if where else text


class Config(BaseModel):
    """Base of every configuration: frozen, unknown keys refused, defaults validated.

    Invalid values raise :class:`~flexreg.errors.ConfigError` with one line naming the field
    and the rule (``n: must be odd (got 4)``). ``"none"``/``"null"`` (any case) stand for None
    in fields that allow None, since TOML has no null.
    """

    model_config = ConfigDict(frozen=True, extra="forbid", validate_default=True)

    def __init__(self, **data: Any) -> None:
        try:
            super().__init__(**data)
        except ValidationError as e:
            raise ConfigError(_one_line(e)) from None

    @model_validator(mode="before")
    @classmethod
    def _none_words(cls, data: Any) -> Any:
        if not isinstance(data, dict):
            return data
        out = dict(data)
        for name, field in cls.model_fields.items():
            v = out.get(name)
            if isinstance(v, str) and v.lower() in NONE_WORDS and _allows_none(field.annotation):
                out[name] = None
        return out

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict of every field (what a result file stores)."""
        return self.model_dump(mode="json")

    def replace(self: C, **changes: Any) -> C:
        """A validated copy with some fields changed (``model_copy`` would skip validation)."""
        return type(self)(**{**self.model_dump(), **changes})


def _read_mapping(path: Path) -> dict[str, Any]:
    if not path.is_file():
        raise ConfigError(f"{path}: no such file")
    suffix = path.suffix.lower()
    try:
        if suffix == ".toml":
            data = tomllib.loads(path.read_text(encoding="utf-8"))
        elif suffix == ".json":
            data = json.loads(path.read_text(encoding="utf-8"))
        else:
            raise ConfigError(f"{path}: a configuration is a .toml or .json file")
    except (tomllib.TOMLDecodeError, json.JSONDecodeError, UnicodeDecodeError) as e:
        raise ConfigError(f"{path}: not valid {suffix[1:].upper()}: {e}") from None
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: expected a table of settings")
    if isinstance(data.get("config"), dict):  # a result file: the configuration it ran with
        data = data["config"]
    return data


def load_config(
    cls: type[C],
    path: str | PathLike[str] | None = None,
    overrides: Mapping[str, Any] | None = None,
) -> C:
    """Build a ``cls`` from its defaults, a file, then overrides (later wins).

    Parameters
    ----------
    cls : type of Config
    path : path-like, optional
        A TOML file (``flexreg config show ... > run.toml``) or a JSON file: either the bare
        settings or a result file whose ``"config"`` key holds them.
    overrides : mapping, optional
        Field name -> value (for instance from :func:`parse_sets` or command-line options);
        a value of None overrides nothing.

    Raises
    ------
    ConfigError
        One line naming the file (when the problem is in it), the field and the rule.
    """
    data: dict[str, Any] = {}
    where = None
    if path is not None:
        data.update(_read_mapping(Path(path)))
        where = str(path)
    extra = {k: v for k, v in (overrides or {}).items() if v is not None}
    try:
        return cls.model_validate({**data, **extra})
    except ValidationError as e:
        loc = e.errors(include_url=False)[0].get("loc", ())
        in_file = bool(loc) and loc[0] in data and loc[0] not in extra
        raise ConfigError(_one_line(e, where if in_file else None)) from None


def _parse_value(text: str) -> Any:
    """A TOML value (``7``, ``0.5``, ``true``, ``"x"``, ``[1, 2]``), else the bare string."""
    if text.strip().lower() in NONE_WORDS:
        return text.strip().lower()  # kept as a word: the model maps it to None where allowed
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text


def parse_sets(items: Iterable[str]) -> dict[str, Any]:
    """``["key=value", ...]`` (repeatable ``--set``) as a dict of typed values.

    >>> parse_sets(["n=7", "ratio=0.8", "refine=false", "features=orb"])
    {'n': 7, 'ratio': 0.8, 'refine': False, 'features': 'orb'}
    """
    out: dict[str, Any] = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise ConfigError(f"--set {item!r}: expected KEY=VALUE")
        out[key.strip()] = _parse_value(value.strip())
    return out


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)  # shortest repr: reads back to the same double
    if isinstance(v, str):
        return json.dumps(v)  # a JSON string is a valid TOML basic string
    if isinstance(v, list | tuple):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    raise ConfigError(f"cannot write {type(v).__name__} to TOML")


def to_toml(config: Config, *, header: str | None = None) -> str:
    """The configuration as TOML, one ``key = value`` per field in declaration order;
    fields that are None are written as comments (``# key = none``).

    :func:`load_config` reads it back to an equal configuration (floats round-trip exactly).
    """
    lines = [f"# {h}" for h in (header.splitlines() if header else [])]
    for name, value in config.model_dump(mode="json").items():
        if value is None:
            lines.append(f"# {name} = none")
        elif isinstance(value, dict):
            raise ConfigError(f"{name}: nested sections are not written by to_toml")
        else:
            lines.append(f"{name} = {_toml_value(value)}")
    return "\n".join(lines) + "\n"
