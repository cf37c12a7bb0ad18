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
flexreg.errors.ConfigError: n: must be at least 3 (got 1)
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
import unicodedata
from collections.abc import Iterable, Mapping
from os import PathLike
from pathlib import Path
from typing import Annotated, Any, TypeVar

from pydantic import (
    AfterValidator,
    BaseModel,
    ConfigDict,
    Field,
    GetCoreSchemaHandler,
    GetJsonSchemaHandler,
    ValidationError,
    model_validator,
)
from pydantic_core import PydanticCustomError, core_schema

from flexreg.errors import ConfigError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

__all__ = [
    "MAX_CONFIG_BYTES",
    "MAX_CONFIG_DEPTH",
    "MAX_GRID_SIZE",
    "MAX_RESULT_BYTES",
    "MAX_THRESHOLD_M",
    "MAX_VOXEL_M",
    "MIN_VOXEL_M",
    "Config",
    "Finite",
    "OddSize",
    "Positive",
    "Seed",
    "ThresholdM",
    "VoxelM",
    "load_config",
    "odd",
    "one_of",
    "parse_sets",
    "to_toml",
]

C = TypeVar("C", bound="Config")

#: Written (and accepted) for "no value": TOML has no null.
NONE_WORDS = ("none", "null")
#: Largest settings file read, bytes: ``flexreg config show`` writes about 10 kB; a bigger
#: file is not a configuration, and parsing it would only cost time and memory.
MAX_CONFIG_BYTES = 1 << 20
#: Largest result JSON read for its ``"config"``, bytes (a survey's poses.json lists every
#: station and link beside the configuration it ran with).
MAX_RESULT_BYTES = 16 << 20
#: Deepest nesting of tables and arrays in a configuration (a file or a ``--set`` value):
#: flexreg's own go three levels deep; deeper ones would only exhaust the parsers' recursion.
MAX_CONFIG_DEPTH = 32
#: Characters that break a line (``str.splitlines``): ``--set`` takes one KEY=VALUE per option.
_LINE_BREAKS = frozenset("\n\r\v\f\x1c\x1d\x1e\x85\u2028\u2029")


def _allows_none(annotation: Any) -> bool:
    if annotation is None or annotation is type(None):
        return True
    origin = typing.get_origin(annotation)
    if origin in (typing.Union, types.UnionType):
        return any(_allows_none(a) for a in typing.get_args(annotation))
    if origin is typing.Annotated:
        return _allows_none(typing.get_args(annotation)[0])
    return False


#: unit words for the field-name suffixes used in flexreg (``threshold_m`` -> metres)
_UNITS = {"m": "metres", "px": "pixels", "deg": "degrees", "rad": "radians", "s": "seconds"}


def _unit(field: str) -> str:
    suffix = field.rpartition("_")[2]
    return f" of {_UNITS[suffix]}" if "_" in field and suffix in _UNITS else ""


def _number(x: Any) -> str:
    return f"{x:g}" if isinstance(x, float) else str(x)


def _bounds(cls: type[BaseModel] | None, field: str) -> dict[str, Any]:
    """The numeric bounds of ``field`` (JSON-schema keywords), also inside ``X | None``."""
    if cls is None:
        return {}
    try:
        prop = cls.model_json_schema()["properties"][field]
    except Exception:  # a message helper never fails its caller
        return {}
    keys = ("minimum", "exclusiveMinimum", "maximum", "exclusiveMaximum", "type")
    for schema in (prop, *prop.get("anyOf", ())):
        if schema.get("type") in ("integer", "number"):
            return {k: schema[k] for k in keys if k in schema}
    return {}


def _choices(cls: type[BaseModel] | None, field: str) -> list[Any]:
    """The allowed values of a ``Literal`` field (its JSON-schema ``enum``)."""
    if cls is None:
        return []
    try:
        prop = cls.model_json_schema()["properties"][field]
    except Exception:  # a message helper never fails its caller
        return []
    for schema in (prop, *prop.get("anyOf", ())):
        if "enum" in schema:
            return list(schema["enum"])
        if "const" in schema:
            return [schema["const"]]
    return []


def _range_text(bounds: dict[str, Any], field: str) -> str:
    """``must be in (0, 1]``, ``must be a positive number of metres``, ``must be at least 8``."""
    lo = ("(", bounds["exclusiveMinimum"]) if "exclusiveMinimum" in bounds else None
    lo = ("[", bounds["minimum"]) if "minimum" in bounds else lo
    hi = (")", bounds["exclusiveMaximum"]) if "exclusiveMaximum" in bounds else None
    hi = ("]", bounds["maximum"]) if "maximum" in bounds else hi
    kind = "integer" if bounds.get("type") == "integer" else "number"
    if lo and hi:
        return f"must be in {lo[0]}{_number(lo[1])}, {_number(hi[1])}{hi[0]}"
    if lo == ("(", 0):
        return f"must be a positive {kind}{_unit(field)}"
    if lo == ("[", 0):
        return f"must be a non-negative {kind}{_unit(field)}"
    if lo:
        return f"must be {'at least' if lo[0] == '[' else 'greater than'} {_number(lo[1])}"
    if hi:
        return f"must be {'at most' if hi[0] == ']' else 'less than'} {_number(hi[1])}"
    return "is out of range"


_RANGE_ERRORS = ("greater_than", "greater_than_equal", "less_than", "less_than_equal")
#: pydantic error types whose message names the allowed values already (no "got" needed)
_NO_GOT = ("missing", "extra_forbidden", "unknown_choice")


def _message(err: Any, field: str, cls: type[BaseModel] | None) -> str:
    """One pydantic error as a short rule: ``must be in (0, 1]``, ``must be one of a, b``."""
    kind = err.get("type")
    got = err.get("input")
    if kind in _RANGE_ERRORS:
        return _range_text(_bounds(cls, field) or _ctx_bounds(err, got), field)
    if kind == "literal_error" and _choices(cls, field):
        return "must be one of " + ", ".join(str(c) for c in _choices(cls, field))
    if kind == "finite_number":
        return f"must be a finite number{_unit(field)}"
    if kind == "extra_forbidden":
        known = ", ".join(cls.model_fields) if cls is not None else ""
        return "unknown setting" + (f"; known: {known}" if known else "")
    if kind == "missing":
        return "required"
    msg = str(err.get("msg", "invalid value")).removeprefix("Value error, ")
    if msg.startswith("Input should be "):
        msg = "must be " + msg.removeprefix("Input should be ")
    return msg


def _shown(value: Any, limit: int = 60) -> str:
    """``repr(value)``, shortened to about ``limit`` characters (a message stays one line)."""
    if isinstance(value, int) and not isinstance(value, bool) and value.bit_length() > 200:
        return f"a number of {len(str(abs(value)))} digits"
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _ctx_bounds(err: Any, got: Any) -> dict[str, Any]:
    names = {"gt": "exclusiveMinimum", "ge": "minimum", "lt": "exclusiveMaximum", "le": "maximum"}
    out = {names[k]: v for k, v in (err.get("ctx") or {}).items() if k in names}
    out["type"] = "integer" if isinstance(got, int) else "number"
    return out


def _one_line(
    e: ValidationError,
    where: str | None = None,
    cls: type[BaseModel] | None = None,
    names: Mapping[str, str] | None = None,
) -> str:
    """The first problem of a pydantic error as ``[where: ]field: rule (got value)``; ``names``
    renames fields (for instance to the command-line option that set them)."""
    err = e.errors(include_url=False)[0]
    field = ".".join(str(p) for p in err.get("loc", ())) or "value"
    got = err.get("input")
    text = f"{(names or {}).get(field, field)}: {_message(err, field, cls)}"
    if err.get("type") not in _NO_GOT and not isinstance(got, dict):
        text += f" (got {_shown(got)})"
    if len(e.errors()) > 1:
        text += f"; and {len(e.errors()) - 1} more"
    return f"{where}: {text}" if where else text


# ------------------------------------------------------------------------ shared field types


class _OneOf:
    """Field metadata: the value must be one of ``values`` (see :func:`one_of`)."""

    def __init__(self, values: Iterable[Any], noun: str | None) -> None:
        self.values = tuple(values)
        self.noun = noun

    def _check(self, value: Any) -> Any:
        if value in self.values and not isinstance(value, bool):
            return value
        known = ", ".join(str(v) for v in self.values)
        if self.noun is None:
            raise PydanticCustomError("choice", "must be one of {known}", {"known": known})
        raise PydanticCustomError(
            "unknown_choice",
            "unknown {noun} {got}; known: {known}",
            {"noun": self.noun, "got": repr(value), "known": known},
        )

    def __get_pydantic_core_schema__(
        self, source: Any, handler: GetCoreSchemaHandler
    ) -> core_schema.CoreSchema:
        return core_schema.no_info_after_validator_function(self._check, handler(source))

    def __get_pydantic_json_schema__(
        self, schema: core_schema.CoreSchema, handler: GetJsonSchemaHandler
    ) -> dict[str, Any]:
        out = dict(handler(schema))
        out["enum"] = list(self.values)
        return out


def one_of(values: Iterable[Any], noun: str | None = None) -> Any:
    """Metadata for ``Annotated[str, one_of(...)]``: the value must be one of ``values``.

    The message lists them: ``must be one of a, b`` or, with a ``noun``, ``unknown feature
    image 'x'; known: a, b``. The JSON schema carries them as an ``enum``.

    >>> class Demo(Config):
    ...     method: Annotated[str, one_of(("essential", "svd"))] = "svd"
    >>> Demo(method="pnp")
    Traceback (most recent call last):
    ...
    flexreg.errors.ConfigError: method: must be one of essential, svd (got 'pnp')
    """
    return _OneOf(values, noun)


def odd(minimum: int = 3, noun: str = "size", maximum: int | None = None) -> Any:
    """Metadata for ``Annotated[int, odd(...)]``: an odd integer of at least ``minimum`` (and at
    most ``maximum``)."""
    top = "..." if maximum is None else f"... {maximum}"
    rule = f"must be an odd {noun} {minimum}, {minimum + 2}, {minimum + 4}, {top}"

    def check(value: int) -> int:
        if value < minimum or value % 2 == 0 or (maximum is not None and value > maximum):
            raise PydanticCustomError("odd", rule)
        return value

    return AfterValidator(check)


#: Largest Flexion / Bearing Angle grid size n (neighbours (n - 1) / 2 = 49 pixels away); the
#: stages refuse larger ones too, and any n larger than the image.
MAX_GRID_SIZE = 99
#: An odd window or grid size 3 <= n <= MAX_GRID_SIZE (Flexion n x n, Bearing Angle
#: neighbourhoods).
OddSize = Annotated[int, odd(3, "grid size", MAX_GRID_SIZE)]
#: A seed of the random generators (same seed, same result).
Seed = Annotated[int, Field(ge=0)]
#: A finite number > 0 (thresholds, sizes, times).
Positive = Annotated[float, Field(gt=0, allow_inf_nan=False)]
#: Any finite number.
Finite = Annotated[float, Field(allow_inf_nan=False)]
#: Largest inlier distance of keypoint matches, metres: beyond it almost any match is an
#: "inlier" and the transform is whatever the outliers make it.
MAX_THRESHOLD_M = 5.0
#: Voxel sizes an ICP or a baseline can use, metres: below the smallest the voxel grid's
#: indices overflow (and no scanner resolves it), above the largest nothing of a scene is left.
MIN_VOXEL_M, MAX_VOXEL_M = 1e-4, 10.0
#: An inlier distance, metres, in (0, MAX_THRESHOLD_M].
ThresholdM = Annotated[float, Field(gt=0, le=MAX_THRESHOLD_M, allow_inf_nan=False)]
#: A voxel size, metres, in [MIN_VOXEL_M, MAX_VOXEL_M].
VoxelM = Annotated[float, Field(ge=MIN_VOXEL_M, le=MAX_VOXEL_M, allow_inf_nan=False)]


class Config(BaseModel):
    """Base of every configuration: frozen, unknown keys refused, defaults validated.

    Invalid values raise :class:`~flexreg.errors.ConfigError` with one line naming the field
    and the rule (``n: must be an odd grid size 3, 5, 7, ... 99 (got 4)``). ``"none"``/``"null"``
    (any case) stand for None in fields that allow None, since TOML has no null.
    """

    model_config = ConfigDict(frozen=True, extra="forbid", validate_default=True)

    def __init__(self, **data: Any) -> None:
        try:
            super().__init__(**data)
        except ValidationError as e:
            raise ConfigError(_one_line(e, cls=type(self))) from None

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


def _depth(value: Any) -> int:
    """Nesting depth of dicts and lists in ``value`` (a scalar: 0), without recursion."""
    deepest = 0
    stack: list[tuple[Any, int]] = [(value, 0)]
    while stack:
        v, d = stack.pop()
        if isinstance(v, dict):
            v = list(v.values())
        elif not isinstance(v, list):
            continue
        deepest = max(deepest, d + 1)
        if deepest > MAX_CONFIG_DEPTH:
            break
        stack += [(x, d + 1) for x in v]
    return deepest


def _parse_problem(e: BaseException) -> str:
    """The reason a parser gave up, in one line (Python's own wording is long or misleading)."""
    if isinstance(e, RecursionError):
        return f"nested deeper than {MAX_CONFIG_DEPTH} levels"
    text = str(e)
    if "integer string conversion" in text:
        limit = getattr(sys, "get_int_max_str_digits", lambda: 4300)()
        return f"a number of more than {limit} digits"
    return " ".join(text.split())


def _read_mapping(path: Path) -> dict[str, Any]:
    if not path.is_file():
        raise ConfigError(f"{path}: no such file")
    suffix = path.suffix.lower()
    if suffix not in (".toml", ".json"):
        raise ConfigError(f"{path}: a configuration is a .toml or .json file")
    kind = suffix[1:].upper()
    limit = MAX_CONFIG_BYTES if suffix == ".toml" else MAX_RESULT_BYTES
    try:
        with path.open("rb") as f:
            raw = f.read(limit + 1)
    except OSError as e:
        raise ConfigError(f"{path}: cannot be read: {e.strerror or e}") from None
    if len(raw) > limit:
        raise ConfigError(
            f"{path}: larger than {limit // (1 << 20)} MiB; not a {kind} configuration"
        )
    try:
        text = raw.decode("utf-8")
        data = tomllib.loads(text) if suffix == ".toml" else json.loads(text)
    except (ValueError, RecursionError) as e:  # decode errors, number limits, deep nesting
        raise ConfigError(f"{path}: not valid {kind}: {_parse_problem(e)}") from None
    if _depth(data) > MAX_CONFIG_DEPTH:
        raise ConfigError(f"{path}: not valid {kind}: nested deeper than {MAX_CONFIG_DEPTH} levels")
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: expected a table of settings")
    if isinstance(data.get("config"), dict):  # a result file: the configuration it ran with
        data = data["config"]
    return data


def load_config(
    cls: type[C],
    path: str | PathLike[str] | None = None,
    overrides: Mapping[str, Any] | None = None,
    *,
    names: Mapping[str, str] | None = None,
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
    names : mapping, optional
        Field name -> how messages call a value given in ``overrides`` (the command line passes
        its option names, ``{"n": "--n"}``).

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
    # pydantic's own initialiser, not Config.__init__ (and not model_validate, which calls it):
    # the raw ValidationError says where each bad value came from
    config = cls.__new__(cls)
    try:
        BaseModel.__init__(config, **{**data, **extra})
        return config
    except ValidationError as e:
        loc = e.errors(include_url=False)[0].get("loc", ())
        in_file = bool(loc) and loc[0] in data and loc[0] not in extra
        line = _one_line(e, where if in_file else None, cls, None if in_file else names)
        raise ConfigError(line) from None


def _parse_value(text: str, key: str = "value") -> Any:
    """A TOML value (``7``, ``0.5``, ``true``, ``"x"``, ``[1, 2]``), else the bare string.

    Raises
    ------
    ConfigError
        ``--set KEY: ...`` for a value that is TOML but unusable: nested deeper than
        :data:`MAX_CONFIG_DEPTH`, or a number of more digits than Python converts.
    """
    if text.strip().lower() in NONE_WORDS:
        return text.strip().lower()  # kept as a word: the model maps it to None where allowed
    try:
        value = tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text
    except (ValueError, RecursionError) as e:
        raise ConfigError(f"--set {key}: {_parse_problem(e)}") from None
    if _depth(value) > MAX_CONFIG_DEPTH:
        raise ConfigError(f"--set {key}: nested deeper than {MAX_CONFIG_DEPTH} levels")
    return value


def parse_sets(items: Iterable[str]) -> dict[str, Any]:
    """``["key=value", ...]`` (repeatable ``--set``) as a dict of typed values.

    One KEY=VALUE per item: line breaks and other control characters are refused (TOML
    would read a second line as another setting and drop it).

    >>> parse_sets(["n=7", "ratio=0.8", "refine=false", "features=orb"])
    {'n': 7, 'ratio': 0.8, 'refine': False, 'features': 'orb'}
    >>> parse_sets(["ratio=0.8\\nn=9"])
    Traceback (most recent call last):
    ...
    flexreg.errors.ConfigError: --set: one KEY=VALUE per option; got a line break
    """
    out: dict[str, Any] = {}
    for item in items:
        if any(ch in _LINE_BREAKS for ch in item):
            raise ConfigError("--set: one KEY=VALUE per option; got a line break")
        bad = next((ch for ch in item if unicodedata.category(ch) == "Cc"), None)
        if bad is not None:
            raise ConfigError(f"--set: got a control character ({bad!r}) in {item!r}")
        key, sep, value = item.partition("=")
        if not sep or not key.strip() or not key.strip().isprintable() or " " in key.strip():
            raise ConfigError(f"--set {_shown(item)}: expected KEY=VALUE")
        out[key.strip()] = _parse_value(value.strip(), key.strip())
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
        return _toml_string(v)
    if isinstance(v, list | tuple):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    raise ConfigError(f"cannot write {type(v).__name__} to TOML")


def _toml_string(text: str) -> str:
    """``text`` as a TOML basic string: quotes, backslashes and control characters escaped,
    everything else as it is (JSON's escapes would split characters beyond U+FFFF into
    surrogate pairs, which TOML refuses)."""
    out = []
    for ch in text:
        o = ord(ch)
        if ch in '"\\':
            out.append("\\" + ch)
        elif o < 0x20 or o == 0x7F:
            out.append(f"\\u{o:04x}")
        elif 0xD800 <= o <= 0xDFFF:
            raise ConfigError(f"{text!r}: not valid text (undecodable bytes)")
        else:
            out.append(ch)
    return '"' + "".join(out) + '"'


def to_toml(config: Config, *, header: str | None = None) -> str:
    """The configuration as TOML, one ``key = value`` per field in declaration order; fields
    that are None are written as comments (``# key = none``), nested configurations as
    ``[name]`` tables after the plain fields.

    :func:`load_config` reads it back to an equal configuration (floats round-trip exactly).
    """
    lines = [f"# {h}" for h in (header.splitlines() if header else [])]
    tables: list[str] = []
    for name, value in config.model_dump(mode="json").items():
        if isinstance(value, dict):
            tables += ["", f"[{name}]", *_toml_lines(value, name)]
        else:
            lines += _toml_lines({name: value}, "")
    return "\n".join(lines + tables) + "\n"


def _toml_lines(values: Mapping[str, Any], table: str) -> list[str]:
    lines = []
    for name, value in values.items():
        if value is None:
            lines.append(f"# {name} = none")
        elif isinstance(value, dict):
            raise ConfigError(f"{table}.{name}: tables within tables are not written by to_toml")
        else:
            lines.append(f"{name} = {_toml_value(value)}")
    return lines
