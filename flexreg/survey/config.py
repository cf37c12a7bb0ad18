"""Every knob of :func:`flexreg.survey.run_survey`, validated in one place."""

from __future__ import annotations

import logging
from typing import Any, Literal

from pydantic import Field, model_validator

from flexreg.config import MAX_VOXEL_M, Config
from flexreg.errors import ConfigError
from flexreg.registration.config import RegistrationConfig

PairsMode = Literal["auto", "all", "sequential"]
StoredPoses = Literal["prior", "check", "ignore"]
#: Finest voxel of the survey's multi-view ICP, metres (1 cm).
MIN_REFINE_VOXEL_M = 0.01
#: Where the stored poses are an earlier registration (``stored_sigma_m`` None): a placed
#: station whose stored pose disagrees with its registered one by more than this is flagged
#: (degrees, metres).
STORED_MAX_DEG, STORED_MAX_M = 1.0, 0.10
#: Open3D's line-process weight under which the pose-graph optimisation prunes an edge
#: (its own default).
PRUNE_THRESHOLD = 0.25
#: A map conflict on a path whose links loops all confirm cuts the most doubtful one and every
#: link of the path whose doubt (free-space conflict ratio) is within this factor of it (else
#: it cuts the links no loop confirms).
MAP_DOUBT_MARGIN = 1.5
#: Two placed stations closer than this (metres) are one viewpoint: they must explain
#: :data:`COINCIDENT_EXPLAINED` of each other (a repeated set-up does; two stations folded
#: onto one spot of a repeating structure do not).
COINCIDENT_M, COINCIDENT_EXPLAINED = 1.0, 0.8
#: Two placed stations "see each other" where each explains at least this share of the
#: other's sample: a pair the final alignment measures.
MIN_EXPLAINED = 0.1
#: Settings of earlier releases the graph's consistency mechanism replaced, at the values
#: they had then: read with a deprecation warning at those values, refused otherwise.
RETIRED: dict[str, Any] = {
    "loop_doubt_min": 0.15,
    "loop_doubt_ratio": 2.0,
    "trust_lone_links": False,
    "uncertain_joins": False,
    "map_judges_loops": True,
    "map_judge_ratio": 3.0,
    "map_joins_groups": True,
    "map_join_min_explained": MIN_EXPLAINED,
    "prune_threshold": PRUNE_THRESHOLD,
    "map_doubt_margin": MAP_DOUBT_MARGIN,
    "map_coincident_m": COINCIDENT_M,
    "map_coincident_explained": COINCIDENT_EXPLAINED,
}

log = logging.getLogger(__name__)


class SurveyConfig(Config):
    """Every knob of a survey; saved in poses.json.

    Attributes
    ----------
    registration : RegistrationConfig
        The pairwise registration of every link (its ``seed`` seeds every link alike).
    pairs : {"auto", "all", "sequential"}
        Candidate links: place recognition plus file-order neighbours (``auto``), every pair,
        or file-order neighbours only. A CSV of pairs is given to :func:`run_survey` instead.
    neighbours : int
        File-order neighbours linked on each side when the names are sequential (``auto`` and
        ``sequential``).
    place_candidates : int
        Best place-recognition matches tried per station (``auto``).
    max_links_per_station : float
        Cap of attempted links, times the number of stations (``auto``).
    proximity_rounds : int
        Extra rounds (``auto``): after a first graph, stations whose solved positions lie
        within ``proximity_m`` are linked when not yet tried (closes loops), then the
        pairs each pose of a link between two groups brings within ``proximity_m`` (the
        loops that would test it), then unplaced stations' next place-recognition
        candidates; each round takes at most its share of the link budget left.
    proximity_m : float, metres
        Distance between solved (or hypothesised) station positions under which a pair is
        tried in a proximity round, and between rough positions (``--positions``) under
        which a pair is linked.
    loop_max_deg : float, degrees
        A link that disagrees by more than this with the cycle it closes is rejected.
    loop_max_m : float, metres
        A link that disagrees by more than this in translation with the cycle it closes is
        rejected (plus ``loop_per_link_m`` per link of the cycle).
    loop_per_link_m : float, metres
        Loop tolerance added per link of the closed cycle (errors add up along a path).
    residual_factor : float
        After the optimisation, a link whose residual exceeds this many times the median
        residual of the accepted links is dropped and the graph solved again (worst first).
    residual_floor_m : float, metres
        A link is never dropped for a translation residual under this (``residual_factor``).
    residual_floor_deg : float, degrees
        A link is never dropped for a rotation residual under this (``residual_factor``).
    joint_refine : bool
        The final joint alignment (on by default; ``--no-refine`` skips it): every placed
        station refined together on its overlapping points, each with its 1-sigma accuracy
        and a status (:mod:`flexreg.survey.adjust`). Without it accuracies are unchecked and
        no station is ``verified``.
    refine_voxel_m : float, metres
        Voxel of the stations' adjustment clouds, in [0.01, 10] m (:data:`MIN_REFINE_VOXEL_M`;
        point-to-plane fits of voxel means resolve far under the voxel: 2 cm gives
        sub-millimetre pairs on indoor scans).
    refine_iterations : int
        Most rounds of cloud-to-cloud fits + pose-graph adjustment, in [1, 10]; it stops
        earlier once no pair needs measuring again (none moved by its fit's kernel width).
    tolerance_mm : float, millimetres
        A placed station whose 95 % error (position, or rotation at its median range)
        exceeds this, or at which a pair disagrees with the adjusted poses by more, is
        ``outside_tolerance`` and never verified.
    stored_poses : {"prior", "check", "ignore"}
        Poses the files store per setup (E57 ``pose``, PTX header; identity means none):
        ``prior`` seeds every link between two such stations with the stored relative pose
        (it competes with what the images find on the registration's dense check) and checks
        every placed station against it; ``check`` only checks; ``ignore`` does neither.
    stored_sigma_m : float or None, metres
        How rough the stored poses are (1-sigma of a position): None takes them as an
        earlier registration, and a placed station whose stored pose disagrees with its
        registered one by more than :data:`STORED_MAX_DEG` or :data:`STORED_MAX_M` (after
        the stored frame is tied on the stations that agree) is flagged. Given, they are
        rough priors (a field software's or a sketch's): they decide between each link's
        poses as rough positions do (:mod:`flexreg.survey.positions`) and flag a station
        only beyond three sigma (and 30 degrees about the vertical).
    map_check : bool
        After the graph, score every pair of placed stations of a group (linked or not) on the
        dense check and cut the links no loop confirms between two that contradict each other;
        test a station that a link closing no loop places against the stations loops confirm
        at full resolution, refuted from ``registration.judge.settle_open_share`` of their
        points in each other's open space (:mod:`flexreg.survey.mapcheck`).
    map_radius_m : float, metres
        Pairs of placed stations farther apart than this are not checked.
    map_min_conflict : float
        A pair conflicts when, in either direction, at least this share of one station's
        sample lies in the other's free space (and ``map_conflict_ratio`` holds); and two
        stations see each other from this share explained (a lone station that passed the
        full-resolution test is then held placed right).
    map_conflict_ratio : float
        A pair conflicts only when that share in free space is at least this many times the
        share the other explains (with ``map_min_conflict``).
    map_rounds : int
        Map checks (each after the graph was solved again without the cut links).
    """

    registration: RegistrationConfig = RegistrationConfig()
    pairs: PairsMode = "auto"
    neighbours: int = Field(1, ge=0, le=5)
    place_candidates: int = Field(3, ge=0, le=20)
    max_links_per_station: float = Field(6.0, gt=0, le=100)
    proximity_rounds: int = Field(2, ge=0, le=5)
    proximity_m: float = Field(12.0, gt=0)
    loop_max_deg: float = Field(0.3, gt=0, le=30)
    loop_max_m: float = Field(0.03, gt=0)
    loop_per_link_m: float = Field(0.01, ge=0)
    residual_factor: float = Field(10.0, gt=1)
    residual_floor_m: float = Field(0.02, gt=0)
    residual_floor_deg: float = Field(0.2, gt=0)
    joint_refine: bool = True
    refine_voxel_m: float = Field(0.02, ge=MIN_REFINE_VOXEL_M, le=MAX_VOXEL_M, allow_inf_nan=False)
    refine_iterations: int = Field(4, ge=1, le=10)
    tolerance_mm: float = Field(10.0, gt=0, le=1e4, allow_inf_nan=False)
    stored_poses: StoredPoses = "prior"
    stored_sigma_m: float | None = Field(None, gt=0, le=1e3, allow_inf_nan=False)

    @model_validator(mode="before")
    @classmethod
    def _retired(cls, data: Any) -> Any:
        """``stored_max_deg`` / ``stored_max_m`` and the :data:`RETIRED` settings of older
        runs, at their values then: read, with a deprecation warning."""
        if not isinstance(data, dict):
            return data
        out = dict(data)
        for key, was in (("stored_max_deg", STORED_MAX_DEG), ("stored_max_m", STORED_MAX_M)):
            if key in out:
                if out.pop(key) != was:
                    raise ConfigError(
                        f"{key}: no longer a setting (fixed at {was:g}; rough stored poses: "
                        "stored_sigma_m)"
                    )
                log.warning("setting %s is deprecated: fixed at %g now", key, was)
        old = sorted(k for k in RETIRED if k in out)
        for key in old:
            if out.pop(key) != RETIRED[key]:
                raise ConfigError(
                    f"{key}: no longer a setting (it was {RETIRED[key]}): the graph keeps the "
                    "hypotheses that agree around cycles (docs/survey.md); to place a station, "
                    "--link, --positions or --pairs +FILE.csv"
                )
        if old:
            log.warning(
                "settings %s are deprecated: the graph decides without them", ", ".join(old)
            )
        return out

    map_check: bool = True
    map_radius_m: float = Field(60.0, gt=0)
    map_min_conflict: float = Field(0.03, gt=0, le=1)
    map_conflict_ratio: float = Field(1.0, gt=0)
    map_rounds: int = Field(4, ge=1, le=20)


__all__ = [
    "COINCIDENT_EXPLAINED",
    "COINCIDENT_M",
    "MAP_DOUBT_MARGIN",
    "MIN_EXPLAINED",
    "MIN_REFINE_VOXEL_M",
    "PRUNE_THRESHOLD",
    "RETIRED",
    "STORED_MAX_DEG",
    "STORED_MAX_M",
    "PairsMode",
    "StoredPoses",
    "SurveyConfig",
]
