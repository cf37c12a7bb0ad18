"""Options shared by the commands: ``--config FILE``, repeatable ``--set KEY=VALUE``, the
options that alias configuration fields, and the checks of output paths.

Every command that runs an application builds its configuration the same way
(:func:`build_config`): the defaults, then the ``--config`` file (TOML, or a result JSON whose
``"config"`` it reruns), then the command's own options and ``--set`` (the same field given
both ways is refused). Values are checked by the configuration itself; only output paths are
checked here, before any input is read.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Annotated, Any, TypeVar

import typer

from flexreg.config import Config, load_config, parse_sets
from flexreg.errors import ConfigError

C = TypeVar("C", bound=Config)

#: whether ``--overwrite`` was given (set by the root options, read by the output checks)
_OVERWRITE = [False]


def set_overwrite(flag: bool) -> None:
    """``--overwrite``: outputs that exist already are replaced instead of refused."""
    _OVERWRITE[0] = bool(flag)


def overwrite_allowed() -> bool:
    return _OVERWRITE[0]


def _refuse_existing(option: str, path: Path, what: str = "exists") -> None:
    if not _OVERWRITE[0]:
        raise ConfigError(
            f"{option}: {path}: {what} (an earlier result); give --overwrite to replace it"
        )


#: ``--config FILE`` (declare as ``config_file: ConfigFileOption = None``)
ConfigFileOption = Annotated[
    Path | None,
    typer.Option(
        "--config",
        metavar="FILE",
        help="Settings from a TOML file ('flexreg config show NAME' writes one) or a result "
        "JSON (reruns its 'config'). Options and --set override it.",
    ),
]
#: repeatable ``--set KEY=VALUE`` (declare as ``sets: SetOption = None``)
SetOption = Annotated[
    list[str] | None,
    typer.Option(
        "--set",
        metavar="KEY=VALUE",
        help="Set any configuration field (repeatable), e.g. --set ratio=0.8; "
        "'flexreg config show NAME' lists the fields.",
    ),
]


def with_default(cls: type[Config], field: str, text: str) -> str:
    """Help text of an option that aliases ``field``, ending with the field's default (the
    option itself defaults to None: left out, it overrides nothing)."""
    *tables, name = field.split(".")  # a field of a nested table: "prior.upright"
    for t in tables:
        cls = type(cls.model_fields[t].default)
    default = cls.model_fields[name].default
    if default is None:
        return text
    shown = ("yes" if default else "no") if isinstance(default, bool) else f"{default}"
    return f"{text} [default: {shown}]"


def build_config(
    cls: type[C],
    config_file: Path | None,
    sets: Sequence[str] | None,
    options: Mapping[str, str | tuple[str, ...]],
    *,
    base: Config | None = None,
    **values: Any,
) -> C:
    """The command's configuration: defaults < ``config_file`` < options and ``--set``.

    Parameters
    ----------
    cls : type of Config
    config_file : Path or None
        The ``--config`` file.
    sets : sequence of str or None
        The ``--set KEY=VALUE`` items.
    options : mapping
        Option name -> field it sets (``{"--voxel": "voxel_m"}``), or fields
        (``{"--resolution": ("width", "height")}``), declared once per command.
    base : Config, optional
        Used instead of the class defaults when there is no ``config_file`` (a command whose
        defaults depend on another option, like ``bench --quick``).
    **values
        Field -> the value of its option (None: the option was left out).

    Raises
    ------
    ConfigError
        One line naming the option, ``--set KEY`` or ``FILE: KEY`` at fault and the rule.
    """
    option_of = {
        field: option
        for option, fields in options.items()
        for field in ((fields,) if isinstance(fields, str) else fields)
    }
    unknown = set(values) - set(option_of)
    if unknown:  # a programming error in a command, not a user error
        raise TypeError(f"values without an option: {', '.join(sorted(unknown))}")
    given = {field: v for field, v in values.items() if v is not None}
    overrides = parse_sets(sets or ())
    for field in given:
        if field in overrides:
            raise ConfigError(
                f"{option_of[field]}: also given as --set {field}=...; give it one way"
            )
    names = {field: option_of[field] for field in given}
    names.update({key: f"--set {key}" for key in overrides})
    start = base.model_dump() if base is not None and config_file is None else {}
    return load_config(cls, config_file, {**start, **given, **overrides}, names=names)


def check_outputs(
    outputs: Sequence[tuple[str, Path | None, str | None]],
    *,
    inputs: Iterable[Path | None] = (),
    input_folders: Iterable[Path] = (),
    extra_inputs: Iterable[tuple[str, Path | None]] = (),
    companions: Mapping[str, Sequence[Path]] | None = None,
) -> None:
    """Refuse unusable output paths before anything is read or computed.

    Every output (and every file written beside it) is compared with every input and its
    companion files (a depth PNG's camera sidecar, a 3DTK scan's pose) by file identity, so
    symbolic links, hard links and other spellings of an input are refused too.

    Parameters
    ----------
    outputs : sequence of (option, path or None, suffix or None)
        Each output file, with the suffix it must have (None: any).
    inputs : iterable of Path
        Input scan files no output may overwrite (their companion files included).
    input_folders : iterable of Path
        Input folders whose existing files no output may overwrite.
    extra_inputs : iterable of (option, Path or None)
        Other files the command reads (``--truth``, ``--pairs``, ``--camera``...).
    companions : mapping of option -> paths, optional
        Files an output option writes beside its own path (``project``: the ``.npz`` and the
        camera sidecar).

    Raises
    ------
    ConfigError
        ``--out: T.txt: must be a .json file``, ``... is a folder, not a file``,
        ``... is also an input`` / ``is also --txt``.
    """
    from flexreg.io.files import protect
    from flexreg.io.safety import find_clash, input_files

    given = [(option, path, suffix) for option, path, suffix in outputs if path is not None]
    for option, path, suffix in given:
        if suffix is not None and path.suffix.lower() != suffix:
            raise ConfigError(f"{option}: {path}: must be a {suffix} file")
        if path.is_dir():
            raise ConfigError(f"{option}: {path}: is a folder, not a file")
        blocked = next((q for q in path.parents if q.exists() and not q.is_dir()), None)
        if blocked is not None:
            raise ConfigError(
                f"{option}: {path}: cannot be made: {blocked} is a file, not a folder"
            )
    read: list[tuple[str, Path]] = []
    for p in inputs:
        if p is not None:
            files = input_files(p)
            read.append(("an input", files[0]))
            read += [(f"the companion file of input {p}", c) for c in files[1:]]
    read += [(f"the {option} input", p) for option, p in extra_inputs if p is not None]
    protect(*(p for _, p in read))  # refused again at write time, whatever writes it
    written: list[tuple[str, Path]] = []
    for option, path, _ in given:
        written.append((option, path))
        written += [(option, c) for c in (companions or {}).get(option, ())]
    clash = find_clash(written, read)
    if clash is not None:
        option, path, what = clash
        why = "" if what.startswith("--") else "; refusing to overwrite it"
        raise ConfigError(f"{option}: {path}: is also {what}{why}")
    folders = [f.resolve() for f in input_folders]
    for option, path in written:
        key = path.resolve()
        if path.exists() and any(f in key.parents for f in folders):
            raise ConfigError(f"{option}: {path}: would overwrite a file of the input")
    for option, path in written:
        if path.exists() or path.is_symlink():
            _refuse_existing(option, path)


def check_out_folder(
    option: str,
    folder: Path | None,
    inputs: Iterable[Path] = (),
    *,
    keep: tuple[str, ...] = (),
    kept: str = "",
) -> None:
    """Refuse an output folder that is a file, one of the inputs, or holds anything (but the
    entries named in ``keep``) unless ``--overwrite`` was given. The refusal names the
    results an earlier run recorded there (what ``--overwrite`` replaces) and, when a
    ``keep`` entry is there, says that it stays (``kept``: what it is).

    With ``--overwrite``, files of the same names are replaced, and the files an earlier run
    recorded as its own in the folder's manifest that this run does not write again are
    removed once the new ones are in place (:func:`flexreg.io.files.replace_folder`; never an
    input of the command, never the ``keep`` entries, nothing at all if the command fails).
    Anything else in the folder (the user's) is left alone, and said so. Every run records
    its files in the manifest, and holds the folder while it runs: a second run writing
    into it meanwhile is refused in one line.

    Parameters
    ----------
    option : str
    folder : Path or None
    inputs : iterable of Path
    keep : tuple of str
        Top-level entries that are not results and stay (``survey``: its ``cache``).
    kept : str
        What the ``keep`` entries hold and why keeping them matters, for the refusal.
    """
    from flexreg.io.files import LOCK, MANIFEST, read_manifest, replace_folder

    if folder is None:
        return
    if folder.exists() and not folder.is_dir():
        raise ConfigError(f"{option}: {folder}: exists and is not a folder")
    for p in inputs:
        if p.resolve() == folder.resolve():
            raise ConfigError(f"{option}: {folder}: is also an input")
    ours = (*keep, MANIFEST, LOCK)  # a cache, and flexreg's records of the folder
    if folder.is_dir() and any(e.name not in ours for e in folder.iterdir()):
        there = [k for k in keep if (folder / k).exists()]
        stays = f"; {', '.join(str(folder / k) for k in there)} {kept or 'stays'}" if there else ""
        earlier = [
            r
            for r in read_manifest(folder)
            if r.split("/", 1)[0] not in keep and (folder / r).is_file()
        ]
        if not _OVERWRITE[0]:
            what = (
                f"holds the results of an earlier run ({_listing(earlier)}); give --overwrite "
                "to replace them"
                if earlier
                else "is a folder that is not empty (an earlier result); give --overwrite to "
                "replace it"
            )
            raise ConfigError(f"{option}: {folder}: {what}{stays}")
    replace_folder(folder, keep)


def _listing(files: Sequence[str], most: int = 6) -> str:
    """Relative paths in a few words: a folder's files as ``NAME/`` with their count.

    >>> _listing(["poses.json", "stations/a.txt", "stations/b.txt", "merged.ply"])
    'merged.ply, poses.json, stations/ (2 files)'
    """
    top: dict[str, int] = {}
    for f in files:
        head, _, rest = f.partition("/")
        key = head + "/" if rest else head
        top[key] = top.get(key, 0) + 1
    names = [k if not k.endswith("/") else f"{k} ({_files(n)})" for k, n in sorted(top.items())]
    more = f" and {len(names) - most} more" if len(names) > most else ""
    return ", ".join(names[:most]) + more


def _files(n: int) -> str:
    return f"{n} file" + ("" if n == 1 else "s")


def removed_line(folder: Path, why: str = "") -> str | None:
    """One line naming the files an earlier run wrote into ``folder`` that this run removes
    when it ends (it did not write them again; :func:`flexreg.io.files.superseded`), with
    ``why`` after them; None when there are none."""
    from flexreg.io.files import superseded

    gone = superseded(folder)
    if not gone:
        return None
    return f"{folder}: removing the earlier run's {_listing(gone)}{why}"
