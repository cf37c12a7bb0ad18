"""Stations of a survey: the scan files, their preparation once, and the cache.

Each station is prepared once (:meth:`flexreg.registration.Registration.prepare`) and stored in
``DIR/cache/`` under a key made of the file's content (SHA-256) and the registration
configuration, so a re-run, or a run with stations added, prepares only what is new. Next to
each prepared station the cache holds its *global descriptor* (a few hundred of its strongest
keypoints with their 3D points, a few kilobytes) for place recognition
(:mod:`flexreg.survey.pairs`).

The cache holds data only: each entry is an ``.npz`` archive of plain numpy arrays, read with
``allow_pickle=False``, with JSON metadata (``__meta__``: the layout's :data:`CACHE_SCHEMA`,
the entry's kind, the scan's content hash and configuration hash) and a SHA-256 digest over
the metadata and every array (``__digest__``), checked on every read (:func:`write_entry`,
:func:`read_entry`). A prepared station is stored as the tree and arrays of
:func:`~flexreg.registration.preparation.prepared_to_arrays`. A missing, damaged
(truncated, altered, unreadable) or foreign entry is never trusted: the station is prepared
again, with one warning naming the file and the reason. Nothing in the cache is ever
unpickled or executed, so a cache on a shared mount cannot run code.

A prepared station is what :meth:`~flexreg.registration.Registration.align` needs and no
more: the scan's full point list is dropped when the refinement works on the range images
(the default projective point-to-plane ICP reads only the images and their samples), so a
cached station of 1024x512 holds about 45 MB (range image, normals, the dense check's images
and samples, keypoints). Only the stations of the link at hand are in memory; each worker
keeps the last :data:`KEEP_LOADED` it loaded.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import time
import zipfile
import zlib
from collections import OrderedDict
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from flexreg._version import __version__
from flexreg.core.range_image import RangeImage
from flexreg.core.scan import Scan
from flexreg.core.transforms import is_rigid
from flexreg.errors import FlexregError, InputError
from flexreg.io import read_scan, read_working_scan
from flexreg.io.info import pose_stored
from flexreg.io.origin import centring_problem, recentre
from flexreg.io.pointcloud import is_mesh
from flexreg.io.setups import list_setups
from flexreg.registration.config import RegistrationConfig
from flexreg.registration.pipeline import PreparedScan, Registration
from flexreg.registration.preparation import prepared_from_arrays, prepared_to_arrays
from flexreg.stages.refinement import uses_projective

log = logging.getLogger(__name__)

#: suffixes a folder contributes (depth PNGs need a camera; .npy/.bin carry no station grid)
FOLDER_SUFFIXES = (".ptx", ".e57", ".ply", ".pcd", ".las", ".laz", ".npz", ".3d")
#: keypoints kept per station for place recognition (strongest lifted ones)
GLOBAL_KEYPOINTS = 300
#: prepared stations a worker keeps loaded (a link needs two; neighbours share stations)
KEEP_LOADED = 4
#: bumped when the cached layout changes (old entries are then ignored)
CACHE_FORMAT = 4
#: the layout of a cache entry (its ``__meta__`` names it; any other is not read)
CACHE_SCHEMA = "flexreg.cache/1"
#: suffixes of a prepared station's entry and of its global descriptor's
PREPARED_SUFFIX, GLOBAL_SUFFIX = ".prepared.npz", ".global.npz"

#: file suffixes that may hold several setups (each becomes a station)
MULTI_SETUP_SUFFIXES = (".e57", ".ptx")

_loaded: OrderedDict[str, PreparedScan] = OrderedDict()
_hashes: dict[tuple[str, int, int], str] = {}


@dataclass(frozen=True)
class Station:
    """One station of the project: a scan file, or one setup of a multi-setup file.

    Attributes
    ----------
    stem : str
        The station's name everywhere: the file name without extension, and for a setup of a
        file holding several ``STEM#N`` (N its index in the file, as ``FILE#N`` reads it).
    path : Path
        The scan file.
    setup : int or None
        The setup's index in a multi-setup file (None: the file holds one scan).
    setup_name : str or None
        The name the file gives the setup (E57 ``name``).
    origin : (float, float, float) or None
        Where the scanner stood in the file's frame, metres (``--origins``: points in project
        coordinates); the station is registered about it (:mod:`flexreg.survey.frames`).
    """

    stem: str
    path: Path
    setup: int | None = None
    setup_name: str | None = None
    origin: tuple[float, float, float] | None = None

    @property
    def ref(self) -> str:
        """How to read this station: ``FILE`` or ``FILE#N``."""
        return str(self.path) if self.setup is None else f"{self.path}#{self.setup}"


@dataclass(frozen=True)
class GlobalDescriptor:
    """What place recognition knows of one station.

    Attributes
    ----------
    descriptors : (K, D) float32 or uint8
        The strongest lifted keypoints' descriptors.
    points : (K, 3) float64, metres
        Their 3D points in the scanner frame.
    binary : bool
        Hamming descriptors.
    """

    descriptors: NDArray[Any]
    points: NDArray[np.float64]
    binary: bool


@dataclass(frozen=True)
class Prepared:
    """The outcome of preparing one station (small: it travels back from the workers).

    Attributes
    ----------
    stem : str
    cache_file : str or None
        The prepared station in the cache (None: unreadable).
    points : int
        Valid returns of the scan.
    computed : bool
        Prepared now (False: found in the cache).
    seconds : float
    error : str or None
        The one-line error of an unreadable station.
    T_world_scanner : (4, 4) float64 or None
        The pose the file stores for this setup (E57 ``pose``, PTX header); None when it
        stores none (identity).
    fingerprint : (int, int, str) or None
        The file as it was prepared: size (bytes) and modification time (ns), taken before
        its content was hashed, and that SHA-256 (:func:`unchanged` checks a later read).
    read_seconds : float
        Of ``seconds``, those spent reading the file: hashing its content (every run: the
        cache key) and, when prepared now, reading its points.
    """

    stem: str
    cache_file: str | None
    points: int
    computed: bool
    seconds: float
    error: str | None = None
    T_world_scanner: NDArray[np.float64] | None = None
    fingerprint: tuple[int, int, str] | None = None
    read_seconds: float = 0.0


def find_scans(paths: list[Path] | tuple[Path, ...]) -> list[Path]:
    """The scan files among ``paths``: files as given, folders by :data:`FOLDER_SUFFIXES`.

    Folders are listed (not recursively) in name order; hidden files are skipped, and so are
    PLY triangle meshes (a model of the site, such as the ``scene.ply`` that ``flexreg synth``
    writes beside its stations, is not a station): each skipped mesh is logged as a warning. A
    file named explicitly is always taken.

    Raises
    ------
    InputError
        A path that does not exist, or a folder without any scan file.
    """
    found: list[Path] = []
    for p in paths:
        if p.is_dir():
            listed = sorted(
                f
                for f in p.iterdir()
                if f.is_file()
                and not f.name.startswith(".")
                and f.suffix.lower() in FOLDER_SUFFIXES
            )
            meshes = [f for f in listed if f.suffix.lower() == ".ply" and is_mesh(f)]
            for f in meshes:
                log.warning("%s: a triangle mesh, not a scan: skipped (name it to survey it)", f)
            inside = [f for f in listed if f not in meshes]
            if not inside:
                also = f"; skipped {len(meshes)} mesh file(s)" if meshes else ""
                raise InputError(
                    p, f"no scan files in this folder ({', '.join(FOLDER_SUFFIXES)}){also}"
                )
            found.extend(inside)
        elif p.exists():
            found.append(p)
        else:
            raise InputError(p, "no such file or folder")
    return found


def _setups_of(path: Path) -> list[Station]:
    """The stations of one file: one per setup of an E57 / PTX file holding several (listed
    from the headers, no point read), else the file itself. A file whose setups cannot be
    listed stays one station; its preparation then reports what is wrong with it."""
    if path.suffix.lower() not in MULTI_SETUP_SUFFIXES:
        return [Station(path.stem, path)]
    try:
        setups = list_setups(path)
    except (FlexregError, OSError, ValueError) as e:
        log.debug("%s: setups not listed (%s)", path, e)
        return [Station(path.stem, path)]
    if len(setups) == 1:
        return [Station(path.stem, path)]
    return [Station(f"{path.stem}#{s.index}", path, s.index, s.name) for s in setups]


def stations_of(files: list[Path]) -> list[Station]:
    """The stations of the given files: one per file, or one per setup of a file that holds
    several (every setup of every file).

    Raises
    ------
    InputError
        Two stations with the same name (every output is keyed by it).
    """
    seen: dict[str, Station] = {}
    for f in files:
        for st in _setups_of(f):
            old = seen.get(st.stem)
            if old is not None and (old.path.resolve(), old.setup) != (f.resolve(), st.setup):
                raise InputError(f, f"same station name {st.stem!r} as {old.path}")
            seen.setdefault(st.stem, st)
    return list(seen.values())


def file_hash(path: Path, *, chunk: int = 1 << 23) -> str:
    """SHA-256 of a file's content (hex), read in chunks.

    Remembered per process by path, size and modification time, so the setups of one
    project file are hashed once per worker, not once per setup.
    """
    st = path.stat()
    key = (str(path.resolve()), st.st_size, st.st_mtime_ns)
    hit = _hashes.get(key)
    if hit is not None:
        return hit
    h = hashlib.sha256()
    with path.open("rb") as f:
        while block := f.read(chunk):
            h.update(block)
    _hashes[key] = h.hexdigest()
    return _hashes[key]


def config_hash(config: RegistrationConfig) -> str:
    """SHA-256 (hex) of the registration configuration, the flexreg version and the cache
    layout: anything that changes a prepared station."""
    text = json.dumps(
        {"config": config.to_dict(), "version": __version__, "format": CACHE_FORMAT},
        sort_keys=True,
        default=str,
    )
    return hashlib.sha256(text.encode()).hexdigest()


def cache_paths(
    cache_dir: Path, content: str, config: str, setup: int | None = None
) -> tuple[Path, Path]:
    """The prepared station's entry and its global descriptor's (one per setup of a
    multi-setup file): ``.prepared.npz`` and ``.global.npz`` archives of plain arrays
    (:func:`write_entry`)."""
    base = cache_dir / f"{content[:24]}-{config[:12]}"
    if setup is not None:
        base = base.with_name(f"{base.name}-s{setup}")
    return base.with_name(base.name + PREPARED_SUFFIX), base.with_name(base.name + GLOBAL_SUFFIX)


def _compact(p: PreparedScan) -> PreparedScan:
    """Drop what :meth:`Registration.align` does not read: the scan's own points when the
    refinement works on the range images, else its attributes (colours, intensity)."""
    cfg = p.config
    if cfg.refine and not uses_projective(cfg.icp, cfg.voxel_m) and isinstance(p.scan, Scan):
        return replace(p, scan=Scan(points=p.scan.points, name=p.scan.name))
    return replace(p, scan=p.image)


def global_descriptor(p: PreparedScan, k: int = GLOBAL_KEYPOINTS) -> GlobalDescriptor:
    """The ``k`` strongest lifted keypoints of a prepared station and their 3D points."""
    kp = p.keypoints
    idx = np.flatnonzero(kp.lifted)
    order = np.argsort(-kp.features.response[idx], kind="stable")[:k]
    idx = np.sort(idx[order])
    return GlobalDescriptor(
        descriptors=np.ascontiguousarray(kp.features.descriptors[idx]),
        points=np.ascontiguousarray(kp.points[idx], dtype=np.float64),
        binary=bool(kp.features.binary),
    )


def _atomic_bytes(path: Path, write: Any) -> None:
    """Write through a temporary sibling unique to this process, then rename (workers on
    several machines may prepare the same station at once: the last rename wins, and both
    wrote the same content)."""
    tmp = path.with_name(f".{path.name}.{os.getpid()}.{time.monotonic_ns()}.partial")
    try:
        with tmp.open("wb") as f:
            write(f)
        tmp.replace(path)
    finally:
        tmp.unlink(missing_ok=True)


class CacheEntryError(ValueError):
    """A cache entry that cannot be used: unreadable, truncated, altered, of another layout
    or of another station (the message says which, in a few words)."""


def _digest(meta: bytes, arrays: dict[str, NDArray[Any]]) -> str:
    """SHA-256 (hex) over the metadata and every array (name, type, shape and bytes), in
    name order."""
    h = hashlib.sha256(meta)
    for key in sorted(arrays):
        a = arrays[key]
        h.update(f"\0{key}\0{a.dtype.str}\0{a.shape}\0".encode())
        h.update(a.data if a.flags.c_contiguous else np.ascontiguousarray(a).data)
    return h.hexdigest()


def write_entry(
    path: Path, kind: str, arrays: dict[str, NDArray[Any]], meta: dict[str, Any]
) -> None:
    """Store a cache entry: ``arrays`` (plain numpy arrays, no objects) in an ``.npz``
    archive with ``__meta__`` (UTF-8 JSON: :data:`CACHE_SCHEMA`, ``kind`` and ``meta``) and
    ``__digest__`` (SHA-256 hex over both), written atomically."""
    if any(k.startswith("__") for k in arrays):
        raise ValueError("array names starting with __ are the entry's own")
    info = json.dumps(
        {**meta, "schema": CACHE_SCHEMA, "kind": kind}
    ).encode()  # in order: parts precede refs
    digest = _digest(info, arrays).encode()
    own = {
        "__meta__": np.frombuffer(info, dtype=np.uint8),
        "__digest__": np.frombuffer(digest, dtype=np.uint8),
    }
    _atomic_bytes(path, lambda f: np.savez(f, allow_pickle=False, **arrays, **own))


def read_entry(path: Path | str, kind: str) -> tuple[dict[str, Any], dict[str, NDArray[Any]]]:
    """A cache entry's metadata and arrays (:func:`write_entry`), its digest checked.

    Read with ``allow_pickle=False``: a pickle, or an archive holding object arrays, is
    refused, never unpickled.

    Raises
    ------
    CacheEntryError
        Missing, unreadable or truncated; not an entry of this layout or of this ``kind``;
        or its digest does not match its content.
    """
    try:
        z = np.load(path, allow_pickle=False)
        if not isinstance(z, np.lib.npyio.NpzFile):
            raise CacheEntryError("not an npz archive")
        with z:
            arrays = {k: z[k] for k in z.files}
    except FileNotFoundError:
        raise CacheEntryError("missing") from None
    except (OSError, ValueError, EOFError, KeyError, zipfile.BadZipFile, zlib.error) as e:
        if isinstance(e, CacheEntryError):
            raise
        raise CacheEntryError(f"unreadable: {' '.join(str(e).split())[:120]}") from None
    info, digest = arrays.pop("__meta__", None), arrays.pop("__digest__", None)
    if info is None or digest is None or info.dtype != np.uint8 or digest.dtype != np.uint8:
        raise CacheEntryError("not a flexreg cache entry")
    try:
        meta = json.loads(info.tobytes().decode())
    except ValueError:
        raise CacheEntryError("unreadable metadata") from None
    if not isinstance(meta, dict) or meta.get("schema") != CACHE_SCHEMA:
        raise CacheEntryError("another cache layout")
    if meta.get("kind") != kind:
        raise CacheEntryError(f"a {str(meta.get('kind'))[:20]} entry, not a {kind} one")
    if _digest(info.tobytes(), arrays) != digest.tobytes().decode(errors="replace"):
        raise CacheEntryError("digest mismatch (altered or damaged)")
    return meta, arrays


def save_prepared(prepared: PreparedScan, path: Path, **meta: Any) -> None:
    """Store a prepared station as a cache entry of plain arrays (:func:`write_entry`;
    :func:`~flexreg.registration.preparation.prepared_to_arrays`); ``meta`` (JSON values)
    is kept beside it."""
    tree, arrays = prepared_to_arrays(prepared)
    write_entry(path, "prepared", arrays, {**meta, "tree": tree})


def read_prepared(path: Path | str) -> tuple[PreparedScan, dict[str, Any]]:
    """A prepared station stored by :func:`save_prepared`, and its metadata.

    Raises
    ------
    CacheEntryError
        The entry cannot be used (:func:`read_entry`), or does not hold a prepared station.
    """
    meta, arrays = read_entry(path, "prepared")
    try:
        return prepared_from_arrays(meta.pop("tree", None), arrays), meta
    except ValueError as e:
        raise CacheEntryError(str(e)[:160]) from None


def _read_and_prepare(
    station: Station, config: RegistrationConfig
) -> tuple[PreparedScan, int, NDArray[np.float64], bool, float]:
    """The station read and prepared at the lowest peak memory, its number of points, its
    stored pose, whether the file stores one (:func:`flexreg.io.info.pose_stored`) and the
    seconds spent reading it. No
    intensities unless the feature image reads them; the checks' inputs after
    the feature stages (``overlap=False``); when the refinement reads only the range images,
    a PTX or E57 station is read straight into its points and working image
    (:func:`~flexreg.io.read_working_scan`: no grid index), and the points are let go once
    the refinement's sample exists, before the feature stages (``keep_scan=False``: only
    ``prepare`` holds them)."""
    points_needed = config.refine and not uses_projective(config.icp, config.voxel_m)
    image: RangeImage | None = None
    t0 = time.perf_counter()
    if points_needed or config.image == "intensity" or station.origin is not None:
        scan = read_scan(station.ref, intensity=config.image == "intensity")
        if station.origin is not None:
            scan = recentre(scan, station.origin)
    else:  # a PTX or E57 station straight into its points and its working image
        scan, image = read_working_scan(station.ref, max_pixels=config.max_image_pixels)
    if image is None and station.origin is None and (why := centring_problem(scan)):
        raise InputError(
            station.path,
            f"not centred on its scanner: {why}; give the scanner positions in the files' "
            "frames with --origins FILE.csv (rows stem,x,y,z, metres)",
        )
    read_s = time.perf_counter() - t0
    n = len(scan)
    T_world = np.asarray(scan.T_world_scanner, dtype=np.float64)
    explicit = pose_stored(scan)  # a 3DTK .pose file holding the identity is a pose
    held: list[Any] = [scan, image]
    del scan, image  # only prepare holds them now, and lets go of them when it can
    prepared = Registration(config).prepare(
        held.pop(0), image=held.pop(), overlap=False, keep_scan=points_needed
    )
    return _compact(prepared), n, T_world, explicit, read_s


def prepare_station(station: Station, cache_dir: str, config: RegistrationConfig) -> Prepared:
    """Prepare one station unless the cache holds it; store it and its global descriptor.

    Runs on a Dask worker (or in the calling process). An unreadable station is returned with
    its error, not raised, so the rest of the project goes on. A cache entry is used only
    when both of the station's entries read back whole, with matching digests, and were made
    of this file's content and this configuration; else the station is prepared again (one
    warning per unusable entry that exists) and its entries rewritten.
    """
    t0 = time.perf_counter()
    folder = Path(cache_dir)
    try:
        st = station.path.stat()  # before the hash: a later change shows in one or the other
        content = file_hash(station.path)
        fingerprint = (st.st_size, st.st_mtime_ns, content)
        read_s = time.perf_counter() - t0
    except OSError as e:
        return Prepared(station.stem, None, 0, False, 0.0, f"{station.path}: {e.strerror or e}")
    conf = config_hash(config)
    key: dict[str, Any] = {"content": content, "config": conf, "setup": station.setup}
    if station.origin is not None:  # registered about another point: another entry
        key["origin"] = [float(v) for v in station.origin]
    entry, npz = cache_paths(folder, content, conf, station.setup)
    hit = _cached(entry, npz, key)
    if hit is not None:
        n, T_stored = hit
        dt = time.perf_counter() - t0
        return Prepared(station.stem, str(entry), n, False, dt, None, T_stored, fingerprint, read_s)
    try:
        prepared, n, T_world, explicit, dt_read = _read_and_prepare(station, config)
    except (FlexregError, ValueError, MemoryError) as e:
        return Prepared(station.stem, None, 0, False, time.perf_counter() - t0, str(e))
    g = global_descriptor(prepared)
    folder.mkdir(parents=True, exist_ok=True)
    arrays = {
        "descriptors": g.descriptors,
        "points": g.points,
        "binary": np.bool_(g.binary),
        "n_points": np.int64(n),
        "T_world_scanner": T_world,
        "pose_stored": np.bool_(explicit),
    }
    write_entry(npz, "global", {k: np.asarray(v) for k, v in arrays.items()}, key)
    save_prepared(prepared, entry, **key)
    log.info("prepared %s in %.1f s", station.stem, time.perf_counter() - t0)
    dt = time.perf_counter() - t0
    T_stored = _stored_pose(T_world, explicit)
    return Prepared(
        station.stem, str(entry), n, True, dt, None, T_stored, fingerprint, read_s + dt_read
    )


def _cached(
    entry: Path, npz: Path, key: dict[str, Any]
) -> tuple[int, NDArray[np.float64] | None] | None:
    """The number of points and stored pose of a station whose cache entries are usable
    (the prepared station then stays loaded, :data:`KEEP_LOADED`); None, after one warning
    naming the first unusable entry that exists, when it must be prepared again."""
    _loaded.pop(str(entry), None)
    try:
        meta, z = read_entry(npz, "global")
        if {k: meta.get(k) for k in key} != key:
            raise CacheEntryError("made of another scan or configuration")
        n = int(z["n_points"])
        said = bool(z["pose_stored"]) if "pose_stored" in z else None  # older entries: None
        stored = _stored_pose(z["T_world_scanner"], said)
        if z["points"].shape != (len(z["descriptors"]), 3) or z["binary"].shape != ():
            raise CacheEntryError("not a global descriptor")
        found = (n, stored)
    except (CacheEntryError, KeyError, TypeError, ValueError) as e:
        if npz.exists():
            log.warning("%s: unusable cache entry (%s); preparing the station again", npz, e)
        return None
    try:
        prepared, meta = read_prepared(entry)
        if {k: meta.get(k) for k in key} != key:
            raise CacheEntryError("made of another scan or configuration")
    except CacheEntryError as e:
        if entry.exists():
            log.warning("%s: unusable cache entry (%s); preparing the station again", entry, e)
        return None
    _keep(str(entry), prepared)
    return found


def _keep(cache_file: str, prepared: PreparedScan) -> None:
    _loaded[cache_file] = prepared
    _loaded.move_to_end(cache_file)
    while len(_loaded) > KEEP_LOADED:
        _loaded.popitem(last=False)


def unchanged(path: Path, fingerprint: tuple[int, int, str]) -> bool:
    """Whether ``path`` still holds what was prepared (:attr:`Prepared.fingerprint`): the same
    size and modification time, or else the same content (hashed again)."""
    try:
        st = path.stat()
        if (st.st_size, st.st_mtime_ns) == fingerprint[:2]:
            return True
        return file_hash(path) == fingerprint[2]
    except OSError:
        return False


def _stored_pose(T: NDArray[np.float64], stored: bool | None = None) -> NDArray[np.float64] | None:
    """A stored pose worth using: rigid, and stored (``stored``: whether the file says it
    stores one; None: unknown, then the identity, which files write when they store none,
    counts as none)."""
    T = np.asarray(T, dtype=np.float64)
    if T.shape != (4, 4) or not is_rigid(T) or stored is False:
        return None
    if stored is None and np.allclose(T, np.eye(4), rtol=0.0, atol=1e-12):
        return None
    return T


def load_descriptor(cache_file: str) -> GlobalDescriptor:
    """The global descriptor stored beside a prepared station.

    Raises
    ------
    InputError
        The entry is missing or unusable (:func:`read_entry`).
    """
    npz = Path(cache_file.removesuffix(PREPARED_SUFFIX) + GLOBAL_SUFFIX)
    try:
        _, z = read_entry(npz, "global")
        return GlobalDescriptor(z["descriptors"], z["points"], bool(z["binary"]))
    except (CacheEntryError, KeyError, TypeError, ValueError) as e:
        raise InputError(npz, f"cannot read the global descriptor ({e})") from None


def load_prepared(cache_file: str) -> PreparedScan:
    """A prepared station from the cache (:func:`read_prepared`); the last
    :data:`KEEP_LOADED` stay in memory.

    Raises
    ------
    InputError
        The cache entry is missing or unusable (another run cleared it, the cache is not on
        a path every worker sees, or it was damaged since this run prepared it).
    """
    hit = _loaded.get(cache_file)
    if hit is not None:
        _loaded.move_to_end(cache_file)
        return hit
    try:
        prepared, _ = read_prepared(cache_file)
    except CacheEntryError as e:
        raise InputError(
            cache_file, f"cannot read the prepared station ({e}); is the cache shared?"
        ) from None
    _keep(cache_file, prepared)
    return prepared


__all__ = [
    "CACHE_FORMAT",
    "CACHE_SCHEMA",
    "FOLDER_SUFFIXES",
    "GLOBAL_KEYPOINTS",
    "GLOBAL_SUFFIX",
    "KEEP_LOADED",
    "MULTI_SETUP_SUFFIXES",
    "PREPARED_SUFFIX",
    "CacheEntryError",
    "GlobalDescriptor",
    "Prepared",
    "Station",
    "cache_paths",
    "config_hash",
    "file_hash",
    "find_scans",
    "global_descriptor",
    "load_descriptor",
    "load_prepared",
    "prepare_station",
    "read_entry",
    "read_prepared",
    "save_prepared",
    "stations_of",
    "unchanged",
    "write_entry",
]
