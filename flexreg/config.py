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

Pydantic v2 (frozen models, unknown keys refused; a dependency of kiss-icp already): one place
per rule, messages naming the field, models that pickle (Dask) and export a JSON schema.
Tables nest (``[judge]``); ``--set`` reaches into them with dotted keys (``judge.min_overlap``).
"""

from __future__ import annotations

import difflib
import inspect
import json
import math
import re
import sys
import textwrap
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
    "attribute_descriptions",
    "did_you_mean",
    "field_descriptions",
    "load_config",
    "odd",
    "one_of",
    "parse_sets",
    "to_toml",
    "toml_text",
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
        return "unknown setting" + (did_you_mean(field, cls.model_fields) if cls else "")
    if kind == "missing":
        return "required"
    msg = str(err.get("msg", "invalid value")).removeprefix("Value error, ")
    if msg.startswith("Input should be "):
        msg = "must be " + msg.removeprefix("Input should be ")
    return msg


#: Most names an "unknown" message lists when none is close to what was given.
MAX_LISTED = 8


def did_you_mean(given: str, known: Iterable[str]) -> str:
    """The end of an "unknown" message: the closest of the ``known`` names (difflib), all of
    them when there are few, else how many there are.

    >>> did_you_mean("treshold_m", ["threshold_m", "threshold_px", "seed"])
    '; did you mean threshold_m?'
    >>> did_you_mean("x", ["n", "seed"])
    '; known: n, seed'
    """
    names = list(known)
    lower = {n.lower(): n for n in names}
    close = difflib.get_close_matches(given.lower(), list(lower), n=1, cutoff=0.6)
    if close:
        return f"; did you mean {lower[close[0]]}?"
    if len(names) <= MAX_LISTED:
        return "; known: " + ", ".join(names)
    return f"; none of the {len(names)} known names is close ('flexreg config show' lists them)"


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
    inner = (err.get("ctx") or {}).get("error")  # a nested configuration's line, or a rule's
    head, sep, rule = str(inner).partition(": ")
    if isinstance(inner, ConfigError) and sep and " " not in head:
        field, got, text = (head if field == "value" else f"{field}.{head}"), {}, rule
    else:
        text = _message(err, field, cls)
    text = f"{(names or {}).get(field, field)}: {text}"
    if err.get("type") not in _NO_GOT and not isinstance(got, dict):
        text += f" (got {_shown(got)})"
    if len(e.errors()) > 1:
        text += f"; and {len(e.errors()) - 1} more"
    return f"{where}: {text}" if where else text


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


# --------------------------------------------------------- field descriptions from docstrings

#: words of a numpy docstring's type slot that name a type, not a unit
_TYPE_WORDS = frozenset(
    "float int bool str None or of tuple list sequence mapping optional T".split()
)
#: a Sphinx cross-reference (``:func:`a.b` ``, ``:data:`~a.b` ``)
_ROLE = re.compile(r":[a-z]+:`(~?)([^`]+)`")


def _is_type(part: str) -> bool:
    """Whether a piece of a type slot names a type (``float or None``, ``RegistrationConfig``)."""
    words = re.findall(r"[\w/]+", part)
    return bool(words) and all(w in _TYPE_WORDS or w[:1].isupper() for w in words)


def _slot_units(slot: str, count: int) -> list[str]:
    """The unit of each of ``count`` names from a type slot: ``float, metres`` (all of them),
    ``float, degrees and metres`` or ``float, degrees, metres`` (one each)."""
    flat = re.sub(r"\{[^}]*\}|\([^)]*\)", "T", slot)  # choices and tuples hold commas
    units = [p.strip() for p in flat.split(",") if p.strip() and not _is_type(p)]
    if len(units) == 1 and count > 1 and len(units[0].split(" and ")) == count:
        units = units[0].split(" and ")
    if len(units) == count:
        return units
    return [units[0] if len(units) == 1 else ""] * count


def _plain(text: str) -> str:
    """Docstring markup as plain text: ``x`` and cross-references as `x` (a ``~`` reference as
    its last name)."""
    text = _ROLE.sub(lambda m: "`" + (m[2].rpartition(".")[2] if m[1] else m[2]) + "`", text)
    return " ".join(text.replace("``", "`").split())


def _first_sentence(text: str) -> str:
    """``text`` up to its first full stop outside brackets that a new sentence follows."""
    depth = 0
    for i, ch in enumerate(text):
        depth += (ch in "([{") - (ch in ")]}")
        rest = text[i + 1 : i + 3]
        if ch == "." and depth <= 0 and rest[:1] == " " and rest[1:2] in "`(" + _CAPITALS:
            return text[:i]
    return text.removesuffix(".")


_CAPITALS = "ABCDEFGHIJKLMNOPQRSTUVWXYZ"


def _attribute_entries(doc: str) -> list[tuple[str, str, str]]:
    """``(names, type slot, text)`` of each entry of a numpy docstring's Attributes section."""
    lines = inspect.cleandoc(doc).splitlines()
    heads = [i for i, line in enumerate(lines[:-1]) if line.strip() == "Attributes"]
    if not heads or set(lines[heads[0] + 1].strip()) != {"-"}:
        return []
    entries: list[tuple[str, str, list[str]]] = []
    body = lines[heads[0] + 2 :]
    for i, line in enumerate(body):
        if line and not line[0].isspace():
            if i + 1 < len(body) and body[i + 1].strip() and set(body[i + 1].strip()) == {"-"}:
                break  # the next section
            names, _, slot = line.partition(" : ")
            entries.append((names.strip(), slot.strip(), []))
        elif entries:
            entries[-1][2].append(line)
    return [(names, slot, " ".join(text)) for names, slot, text in entries]


def attribute_descriptions(cls: type) -> dict[str, str]:
    """One line per attribute from the Attributes section of ``cls``'s numpy docstring: the
    first sentence of its text, then its unit from the type slot in brackets.

    An entry naming several attributes (``width, height : int``) describes each of them; an
    entry without text describes nothing.

    >>> class Demo:
    ...     '''Attributes
    ...     ----------
    ...     range_m, step_deg : float, metres and degrees
    ...         How far and in which steps (:data:`x.MAX`). More detail.
    ...     '''
    >>> attribute_descriptions(Demo)["step_deg"]
    'How far and in which steps (`x.MAX`) [degrees]'
    """
    out = {}
    for names, slot, text in _attribute_entries(cls.__dict__.get("__doc__") or ""):
        fields = [n.strip() for n in names.split(",")]
        line = _first_sentence(_plain(text))
        for field, unit in zip(fields, _slot_units(slot, len(fields)), strict=True):
            if line:
                out[field] = f"{line} [{unit}]" if unit else line
    return out


class Config(BaseModel):
    """Base of every configuration: frozen, unknown keys refused, defaults validated.

    Invalid values raise :class:`~flexreg.errors.ConfigError` with one line naming the field
    and the rule (``n: must be an odd grid size 3, 5, 7, ... 99 (got 4)``). ``"none"``/``"null"``
    (any case) stand for None in fields that allow None, since TOML has no null.
    """

    model_config = ConfigDict(frozen=True, extra="forbid", validate_default=True)

    @classmethod
    def __pydantic_init_subclass__(cls, **kwargs: Any) -> None:
        """Each field without a ``description`` takes its line of the class docstring's
        Attributes section (:func:`attribute_descriptions`): the docstring stays the one
        place a field's meaning and unit are written, and the JSON schema, ``config show``
        and docs/configuration.md show it."""
        super().__pydantic_init_subclass__(**kwargs)
        described = attribute_descriptions(cls)
        changed = False
        for name, field in cls.model_fields.items():
            if field.description is None and name in described:
                field.description = described[name]
                changed = True
        if changed:
            cls.model_rebuild(force=True)

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
        BaseModel.__init__(config, **_merged(data, _nested(extra)))
        return config
    except ValidationError as e:
        loc = e.errors(include_url=False)[0].get("loc", ())
        field = ".".join(str(p) for p in loc)
        in_file = bool(loc) and loc[0] in data and loc[0] not in extra and field not in extra
        line = _one_line(e, where if in_file else None, cls, None if in_file else names)
        raise ConfigError(line) from None


def _nested(flat: Mapping[str, Any]) -> dict[str, Any]:
    """Dotted keys as nested tables: ``{"judge.min_overlap": 0.3}`` (as ``--set`` takes them)
    becomes ``{"judge": {"min_overlap": 0.3}}``."""
    out: dict[str, Any] = {}
    for key, value in flat.items():
        *tables, name = key.split(".")
        at = out
        for t in tables:
            at[t] = at = dict(at[t]) if isinstance(at.get(t), dict) else {}
        at[name] = value
    return out


def _merged(base: Mapping[str, Any], over: Mapping[str, Any]) -> dict[str, Any]:
    """``over`` on top of ``base``, table by table (a table in ``over`` changes only the
    keys it names)."""
    out = dict(base)
    for key, value in over.items():
        both = isinstance(value, dict) and isinstance(out.get(key), dict)
        out[key] = _merged(out[key], value) if both else value
    return out


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


def toml_text(value: Any) -> str:
    """A JSON-ready value as TOML (``none`` for None, which TOML lacks).

    >>> toml_text(0.1), toml_text("sift"), toml_text([1, 2]), toml_text(None)
    ('0.1', '"sift"', '[1, 2]', 'none')
    """
    return "none" if value is None else _toml_value(value)


def field_descriptions(cls: type) -> dict[str, str]:
    """Field -> its one-line description: a pydantic model's field descriptions, else the
    Attributes section of the class docstring (a dataclass nested in a configuration)."""
    fields = getattr(cls, "model_fields", None)
    if isinstance(fields, dict):
        return {name: f.description for name, f in fields.items() if f.description}
    return attribute_descriptions(cls)


#: Width of the comment lines :func:`to_toml` writes (the project's 100 columns).
TOML_WIDTH = 100


def _comment(text: str | None) -> list[str]:
    if not text:
        return []
    return ["# " + line for line in textwrap.wrap(text, TOML_WIDTH - 2, break_on_hyphens=False)]


def to_toml(config: Config, *, header: str | None = None, comments: bool = True) -> str:
    """The configuration as TOML, one ``key = value`` per field in declaration order; fields
    that are None are written as comments (``# key = none``), nested configurations as
    ``[name]`` tables after the plain fields. With ``comments``, each key follows its
    description (:func:`field_descriptions`) as a comment.

    :func:`load_config` reads it back to an equal configuration (floats round-trip exactly).
    """
    lines = [f"# {h}" for h in (header.splitlines() if header else [])]
    tables: list[str] = []
    notes = field_descriptions(type(config)) if comments else {}
    for name, value in config.model_dump(mode="json").items():
        if isinstance(value, dict):
            inner = getattr(config, name) if comments else None
            tables += _toml_table(inner, value, name, notes.get(name))
        else:
            lines += _toml_lines({name: value}, "", notes)
    if lines[:1] == [""]:
        lines = lines[1:]
    return "\n".join(lines + tables) + "\n"


def _toml_table(config: Any, values: Mapping[str, Any], name: str, note: str | None) -> list[str]:
    """A nested configuration (``values``: its JSON) as ``[name]``, its tables ``[name.x]``."""
    inner = field_descriptions(type(config)) if config is not None else {}
    plain, tables = {}, []
    for key, value in values.items():
        if isinstance(value, dict):
            sub = getattr(config, key, None) if config is not None else None
            tables += _toml_table(sub, value, f"{name}.{key}", inner.get(key))
        else:
            plain[key] = value
    table = _toml_lines(plain, name, inner)
    return ["", *_comment(note), f"[{name}]", *table[table[:1] == [""] :], *tables]


def _toml_lines(values: Mapping[str, Any], table: str, notes: Mapping[str, str]) -> list[str]:
    """``key = value`` lines; a key with a description follows it as a comment, after an
    empty line."""
    lines = []
    for name, value in values.items():
        if isinstance(value, dict):
            raise ConfigError(f"{table}.{name}: tables within tables are not written by to_toml")
        if notes.get(name):
            lines += ["", *_comment(notes[name])]
        if value is None:
            lines.append(f"# {name} = none")
        else:
            lines.append(f"{name} = {_toml_value(value)}")
    return lines
