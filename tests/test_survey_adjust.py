"""The survey's final joint alignment: the cloud-to-cloud figures and information of a pair on
hand-computed cases, the pair fit on a box room, the graph's bridges and 2-edge connectivity,
and accuracies turned into the reference frame."""

from __future__ import annotations

import numpy as np
import pytest

from flexreg.survey.adjust import (
    RADIUS_95,
    REF_SIGMA,
    _accuracy,
    _dense_covariances,
    _two_edge_connected,
    covariances,
)
from flexreg.survey.c2c import (
    CORRELATION_M,
    cloud_figures,
    cluster_covariance,
    fit_groups,
    fit_pair,
    information,
)
from flexreg.survey.links import bridges


def _planes(step: float = 0.05, size: float = 4.0) -> tuple[np.ndarray, np.ndarray]:
    """A floor (z=0) and two walls (x=0, y=0) sampled on a grid: points and unit normals."""
    g = np.arange(step / 2, size, step)
    a, b = np.meshgrid(g, g, indexing="ij")
    a, b, z = a.ravel(), b.ravel(), np.zeros(a.size)
    pts = np.vstack([np.c_[a, b, z], np.c_[z, a, b], np.c_[a, z, b]])
    nrm = np.vstack(
        [np.tile([0.0, 0.0, 1.0], (a.size, 1)), np.tile([1.0, 0, 0], (a.size, 1)),
         np.tile([0.0, 1.0, 0], (a.size, 1))]
    )  # fmt: skip
    return pts, nrm


def test_figures_of_three_planes_by_hand() -> None:
    """Source = target with the floor 4 mm up, one wall 8 mm out, the other 12 mm out: the
    point-to-plane distances are those, every point overlaps, the normals spread evenly."""
    tgt, n = _planes()
    k = len(tgt) // 3
    src = tgt.copy()
    src[:k, 2] += 0.004
    src[k : 2 * k, 0] += 0.008
    src[2 * k :, 1] += 0.012
    f = cloud_figures(tgt, n, src, np.eye(4), 0.05)
    assert f.points == f.source_points == len(src)
    assert f.overlap == 1.0
    assert f.rms_mm == pytest.approx(np.sqrt((16 + 64 + 144) / 3), abs=1e-9)
    assert f.within_6mm == pytest.approx(1 / 3)
    assert f.within_1cm == pytest.approx(2 / 3)
    assert f.balance == pytest.approx(1.0)
    # the inlier RMS leaves the 12 mm wall out; a floor alone has no balance
    g = cloud_figures(tgt, n, src, np.eye(4), 0.05, inlier_m=0.010)
    assert g.rms_mm == pytest.approx(np.sqrt((16 + 64) / 2), abs=1e-9)
    floor = cloud_figures(tgt[:k], n[:k], src[:k], np.eye(4), 0.05)
    assert floor.balance == 0.0 and floor.within_6mm == 1.0


def test_figures_of_a_pair_that_does_not_overlap() -> None:
    tgt, n = _planes(step=0.5, size=2.0)
    f = cloud_figures(tgt, n, tgt + 100.0, np.eye(4), 0.05)
    assert f.points == 0 and f.overlap == 0.0 and f.rms_mm is None  # no number, no NaN


def test_information_by_hand() -> None:
    """Three points in one cell: the mean of their J^T J (J = [p x n, n]) over sigma^2; the
    same points a cell apart each count whole."""
    p = np.array([[0.1, 0.2, 0.3], [0.4, 0.1, 0.2], [0.3, 0.3, 0.1]])
    nrm = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    J = np.hstack([np.cross(p, nrm), nrm])
    w = np.ones(3)
    one = information(p, nrm, w, 0.002, CORRELATION_M)
    np.testing.assert_allclose(one, (J.T @ J) / 3 / 0.002**2, rtol=1e-12)
    apart = p + np.array([[0.0, 0, 0], [5.0, 0, 0], [10.0, 0, 0]])
    Ja = np.hstack([np.cross(apart, nrm), nrm])
    np.testing.assert_allclose(
        information(apart, nrm, w, 0.002, CORRELATION_M), Ja.T @ Ja / 0.002**2, rtol=1e-12
    )
    # a zero weight drops a point
    half = information(p, nrm, np.array([1.0, 0.0, 1.0]), 0.002, CORRELATION_M)
    Jk = J[[0, 2]]
    np.testing.assert_allclose(half, Jk.T @ Jk / 3 / 0.002**2, rtol=1e-12)


def test_cluster_covariance_against_its_formula_by_hand() -> None:
    """Three walls, two cells each: H^-1 S H^-1 with the cells' scores summed by hand; points
    of one cell sharing a residual count as one score (not as independent ones)."""
    rng = np.random.default_rng(3)
    pts, nrm = _planes(step=0.5, size=4.0)
    r = rng.normal(0, 0.002, len(pts))
    w = rng.uniform(0.5, 1.0, len(pts))
    C = cluster_covariance(pts, nrm, w, r, 2.0)
    J = np.hstack([np.cross(pts, nrm), nrm])
    H = sum(w[i] * np.outer(J[i], J[i]) for i in range(len(pts)))
    scores: dict[tuple, np.ndarray] = {}
    for i in range(len(pts)):
        key = tuple(np.floor(pts[i] / 2.0).astype(int))
        scores[key] = scores.get(key, np.zeros(6)) + w[i] * r[i] * J[i]
    S = sum(np.outer(g, g) for g in scores.values()) * len(scores) / (len(scores) - 1)
    Hi = np.linalg.inv(H)
    np.testing.assert_allclose(C, Hi @ S @ Hi, rtol=1e-9, atol=1e-18)
    # one shared residual per cell: larger than the same residuals scattered independently
    parity = np.floor(pts / 2.0).astype(int).sum(axis=1) % 2
    shared = np.where(parity == 1, 0.002, -0.002)
    indep = np.where(np.arange(len(pts)) % 2, 0.002, -0.002)
    big = cluster_covariance(pts, nrm, np.ones(len(pts)), shared, 2.0)
    small = cluster_covariance(pts, nrm, np.ones(len(pts)), indep, 2.0)
    assert np.trace(big[3:, 3:]) > 4 * np.trace(small[3:, 3:])


def _box_cloud(path, T_world_scanner: np.ndarray, rng: np.random.Generator) -> str:
    """An adjustment cloud of a 10 x 8 x 3 m box room with a pillar, seen from a scanner at
    ``T_world_scanner`` (points within 0.02 m noise-free voxels, 1 mm noise)."""
    step = 0.04
    faces = []

    def grid(u0, u1, v0, v1):
        u, v = np.meshgrid(np.arange(u0, u1, step), np.arange(v0, v1, step), indexing="ij")
        return u.ravel(), v.ravel()

    u, v = grid(0, 10, 0, 8)
    faces += [
        (np.c_[u, v, np.zeros_like(u)], [0, 0, 1]),
        (np.c_[u, v, np.full_like(u, 3)], [0, 0, -1]),
    ]
    u, v = grid(0, 10, 0, 3)
    faces += [
        (np.c_[u, np.zeros_like(u), v], [0, 1, 0]),
        (np.c_[u, np.full_like(u, 8), v], [0, -1, 0]),
    ]
    u, v = grid(0, 8, 0, 3)
    faces += [
        (np.c_[np.zeros_like(u), u, v], [1, 0, 0]),
        (np.c_[np.full_like(u, 10), u, v], [-1, 0, 0]),
    ]
    u, v = grid(3, 4, 0, 3)  # a pillar's two faces break the symmetry along x and y
    faces += [
        (np.c_[u, np.full_like(u, 5), v], [0, -1, 0]),
        (np.c_[np.full_like(u, 6), u, v], [-1, 0, 0]),
    ]
    pts = np.vstack([f for f, _ in faces])
    nrm = np.vstack([np.tile(n, (len(f), 1)) for f, n in faces]).astype(float)
    pts = pts + rng.normal(0, 0.001, pts.shape) * nrm  # range noise along the normal
    inv = np.linalg.inv(T_world_scanner)
    p = pts @ inv[:3, :3].T + inv[:3, 3]
    n = nrm @ inv[:3, :3].T
    sparse = np.arange(0, len(p), 7)
    out = str(path)
    np.savez(out, points=p.astype(np.float32), normals=n.astype(np.float32), sparse=sparse,
             median_range_m=np.float64(5.0))  # fmt: skip
    return out


def _pose(deg: float, axis: int, t: tuple[float, float, float]) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    T = np.eye(4)
    rv = np.zeros(3)
    rv[axis] = np.radians(deg)
    T[:3, :3] = Rotation.from_rotvec(rv).as_matrix()
    T[:3, 3] = t
    return T


def test_fit_pair_recovers_a_box_room_from_a_rough_start(tmp_path) -> None:
    """Started 2 cm and 0.3 deg off, the fit lands within 1 mm / 0.01 deg of the truth (1 mm
    noise on 20 000 points: the geometry fixes every axis far better), and its information
    says every axis is fixed (smallest translational sigma under 1 mm)."""
    from flexreg.core.transforms import invert, rotation_error_deg, translation_error_m

    rng = np.random.default_rng(0)
    A, B = _pose(10, 2, (3.0, 2.5, 1.5)), _pose(-25, 2, (7.0, 5.5, 1.6))
    ta = _box_cloud(tmp_path / "a.npz", A, rng)
    tb = _box_cloud(tmp_path / "b.npz", B, rng)
    truth = invert(A) @ B
    start = truth @ _pose(0.3, 2, (0.02, -0.01, 0.005))
    fit = fit_pair(ta, tb, start, 0.02)
    assert rotation_error_deg(fit.T_target_source, truth) < 0.01
    assert translation_error_m(fit.T_target_source, truth) < 0.001
    cov = np.linalg.inv(fit.information)
    assert np.all(np.sqrt(np.diag(cov)[3:]) < 0.001)
    assert fit.figures.overlap > 0.5 and fit.figures.within_6mm > 0.9


def test_bridges_and_two_edge_connectivity() -> None:
    # a triangle a-b-c, a tail c-d, and a double link d-e (two pairs close a loop of two)
    edges = [("a", "b"), ("b", "c"), ("c", "a"), ("c", "d"), ("d", "e"), ("d", "e")]
    assert bridges(edges) == {3}
    assert _two_edge_connected("a", edges) == {"a", "b", "c"}
    assert _two_edge_connected("d", edges) == {"d", "e"}
    assert _two_edge_connected("a", []) == {"a"}


def test_accuracy_turns_the_covariance_into_the_reference_frame() -> None:
    """A station turned 90 deg about z: its own x sigma is the reference's y sigma; the 95 %
    radius is 2.80 times the largest sigma; the rotation's at 20 m."""
    cov = np.diag([1e-8, 4e-8, 9e-8, (1e-3) ** 2, (2e-3) ** 2, (3e-3) ** 2])
    acc = _accuracy(cov, _pose(90, 2, (0, 0, 0)), 20.0)
    np.testing.assert_allclose(acc.sigma_mm, (2.0, 1.0, 3.0), rtol=1e-9)
    np.testing.assert_allclose(np.radians(acc.sigma_deg), (2e-4, 1e-4, 3e-4), rtol=1e-9)
    assert acc.radius95_mm == pytest.approx(RADIUS_95 * 3.0)
    assert acc.rotation95_mm == pytest.approx(RADIUS_95 * 3e-4 * 20.0 * 1e3)


def _corridor_cloud(path, T_world_scanner: np.ndarray, rng: np.random.Generator, *,
                    doorway: bool, voxel: float = 0.02) -> None:  # fmt: skip
    """An adjustment cloud of a 40 m corridor (walls at y = +-1.5 m, floor, ceiling at 3 m, no
    end walls) seen from ``T_world_scanner`` within 12 m; ``doorway``: a door frame across
    it at x = 6 m (two jambs and a lintel) fixes the position along it."""
    step = 0.04
    u, v = np.meshgrid(np.arange(-20, 20, step), np.arange(0, 3, step), indexing="ij")
    u, v = u.ravel(), v.ravel()
    w, f = np.meshgrid(np.arange(-20, 20, step), np.arange(-1.5, 1.5, step), indexing="ij")
    w, f = w.ravel(), f.ravel()
    faces = [
        (np.c_[u, np.full_like(u, -1.5), v], [0, 1, 0]),
        (np.c_[u, np.full_like(u, 1.5), v], [0, -1, 0]),
        (np.c_[w, f, np.zeros_like(w)], [0, 0, 1]),
        (np.c_[w, f, np.full_like(w, 3.0)], [0, 0, -1]),
    ]
    if doorway:
        a, b = np.meshgrid(np.arange(-1.5, 1.5, step), np.arange(0, 3, step), indexing="ij")
        a, b = a.ravel(), b.ravel()
        jamb = (np.abs(a) > 0.5) | (b > 2.2)  # the wall around a 1 m x 2.2 m opening
        faces.append((np.c_[np.full(jamb.sum(), 6.0), a[jamb], b[jamb]], [-1, 0, 0]))
    pts = np.vstack([p for p, _ in faces])
    nrm = np.vstack([np.tile(n, (len(p), 1)) for p, n in faces]).astype(float)
    near = np.linalg.norm(pts - T_world_scanner[:3, 3], axis=1) < 12.0
    pts, nrm = pts[near], nrm[near]
    pts = pts + rng.normal(0, 0.001, pts.shape) * nrm
    inv = np.linalg.inv(T_world_scanner)
    p = (pts @ inv[:3, :3].T + inv[:3, 3]).astype(np.float32)
    n = (nrm @ inv[:3, :3].T).astype(np.float32)
    cells = np.floor(p / np.float32(10 * voxel)).astype(np.int64)
    _, first = np.unique(cells, axis=0, return_index=True)
    np.savez(path, points=p, normals=n, sparse=np.sort(first).astype(np.int64),
             median_range_m=np.float64(5.0))  # fmt: skip


def _adjust_corridor(tmp_path, stations: dict[str, np.ndarray], links, *, doorway: bool):
    """:func:`adjust` on hand-made adjustment clouds (no Dask, no scans): the graph placed
    every station at its true pose and accepted ``links``."""
    from flexreg.survey.adjust import adjust
    from flexreg.survey.c2c import cloud_path
    from flexreg.survey.config import SurveyConfig
    from flexreg.survey.links import GraphSolution, Link

    rng = np.random.default_rng(1)
    tmp_path.mkdir(exist_ok=True)
    files = {}
    for stem, T in stations.items():
        files[stem] = str(tmp_path / f"{stem}.prepared.npz")
        _corridor_cloud(cloud_path(files[stem], 0.02), T, rng, doorway=doorway)
    ref = next(iter(stations))
    poses = {s: np.linalg.inv(stations[ref]) @ T for s, T in stations.items()}
    sol = GraphSolution(ref, poses, [list(stations)], [ref], {}, {}, {})
    ls = [
        Link(t, s, np.linalg.inv(poses[t]) @ poses[s], status="accepted", verdict="confident")
        for t, s in links
    ]
    return adjust(None, sol, ls, [], files, SurveyConfig())


def test_a_corridor_link_slides_and_says_so(tmp_path) -> None:
    """Two stations 3 m apart in a featureless corridor: their fit cannot fix the position
    along it, and the station, placed by that one pair alone, says so and that its 95 % error
    is over the tolerance, with its sigma along the corridor (x) far larger than across it; a
    doorway in view fixes it (placed: one pair alone, well within)."""
    A, B = _pose(0, 2, (0.0, 0.0, 1.5)), _pose(0, 2, (3.0, 0.2, 1.4))
    adj = _adjust_corridor(tmp_path / "plain", {"a": A, "b": B}, [("a", "b")], doorway=False)
    assert adj.status["b"] == "placed" and "one cloud-to-cloud pair" in adj.why["b"]
    assert "95 %" in adj.why["b"] and "over the 10 mm tolerance" in adj.why["b"]
    sx, sy, sz = adj.accuracy["b"].sigma_mm
    assert sx > 10 and sx > 20 * max(sy, sz)
    adj = _adjust_corridor(tmp_path / "door", {"a": A, "b": B}, [("a", "b")], doorway=True)
    assert adj.status["b"] == "placed" and "one cloud-to-cloud pair" in adj.why["b"]
    assert "95 %" not in adj.why["b"]
    assert max(adj.accuracy["b"].sigma_mm) < 2.0
    assert adj.pairs[0].bridge and adj.pairs[0].to_dict()["link_error"] == "unchecked"


def test_an_independent_route_verifies(tmp_path) -> None:
    """Three stations along a corridor with a doorway, linked in a triangle: every pair
    closes a loop, every station is verified, every link error is checked."""
    S = {
        "a": _pose(0, 2, (0.0, 0.0, 1.5)),
        "b": _pose(20, 2, (3.0, 0.3, 1.4)),
        "c": _pose(-15, 2, (8.0, -0.4, 1.5)),
    }
    adj = _adjust_corridor(tmp_path, S, [("a", "b"), ("b", "c"), ("a", "c")], doorway=True)
    assert adj.status == {"a": "verified", "b": "verified", "c": "verified"}
    assert all(not p.bridge and p.residual_m is not None for p in adj.pairs)
    s = adj.summary()
    assert s["pairs_checked"] == 3 and s["bundle_error_mm"] is not None and s["redundancy"] == 6


def test_a_later_round_measures_only_the_pairs_the_solution_moved(tmp_path) -> None:
    """Round 2 fits again only a pair whose relative pose moved by its fit's kernel width
    (TUKEY_C residual sigmas) or more since its fit started (and from where it ended); one
    moved a fifth of it keeps its fit, one turned by twice the kernel at the source's median
    range is fitted again, and a round with nothing moved measures nothing, a pair left out
    included."""
    from flexreg.survey import adjust as adj
    from flexreg.survey.config import SurveyConfig

    rng = np.random.default_rng(1)
    A, B = _pose(10, 2, (3.0, 2.5, 1.5)), _pose(-25, 2, (7.0, 5.5, 1.6))
    clouds = {
        "a": _box_cloud(tmp_path / "a.npz", A, rng),
        "b": _box_cloud(tmp_path / "b.npz", B, rng),
    }
    clouds["c"] = clouds["b"]
    poses = {"a": A, "b": B, "c": B.copy()}
    pairs = [adj.Pair("a", "b", "link"), adj.Pair("a", "c", "overlap")]
    config = SurveyConfig()
    assert adj._measure(None, pairs, clouds, poses, config, None, 1) == 2
    first = [p.fit for p in pairs]
    assert all(f is not None for f in first)
    kernels = [p.kernel_m for p in pairs]
    assert kernels == [adj.TUKEY_C * f.sigma_m for f in first]
    poses["b"] = B @ _pose(0.0, 2, (1.5 * kernels[0], 0.0, 0.0))  # over its kernel
    poses["c"] = B @ _pose(0.0, 2, (0.2 * kernels[1], 0.0, 0.0))  # well inside it
    assert adj._measure(None, pairs, clouds, poses, config, None, 2) == 1
    assert pairs[0].fit is not first[0] and pairs[1].fit is first[1]
    assert adj._measure(None, pairs, clouds, poses, config, None, 3) == 0
    turn = np.degrees(2 * kernels[1] / adj.median_range(clouds["c"]))
    poses["c"] = B @ _pose(turn, 2, (0.0, 0.0, 0.0))
    assert adj._measure(None, pairs, clouds, poses, config, None, 4) == 1
    assert pairs[1].fit is not first[1]
    pairs[1].fit = None  # left out by the adjustment: measured again only once moved
    assert adj._measure(None, pairs, clouds, poses, config, None, 5) == 0


def test_a_pair_the_solution_brought_to_its_fits_end_is_not_measured_again(tmp_path) -> None:
    """A fit started 2 cm and 0.1° off (several kernels) ends at the pair's optimum; once the
    solution holds the pair there (or where that fit started), ICP would end at the same
    place: no later round measures it again; one that holds it away from both does."""
    from flexreg.core.transforms import translation_error_m
    from flexreg.survey import adjust as adj
    from flexreg.survey.config import SurveyConfig

    rng = np.random.default_rng(3)
    A, B = _pose(10, 2, (3.0, 2.5, 1.5)), _pose(-25, 2, (7.0, 5.5, 1.6))
    clouds = {
        "a": _box_cloud(tmp_path / "a.npz", A, rng),
        "b": _box_cloud(tmp_path / "b.npz", B, rng),
    }
    off = B @ _pose(0.1, 2, (0.015, -0.01, 0.005))
    poses = {"a": A, "b": off}
    pairs = [adj.Pair("a", "b", "link")]
    config = SurveyConfig()
    assert adj._measure(None, pairs, clouds, poses, config, None, 1) == 1
    f = pairs[0].fit
    assert f is not None and 0.015 > 2 * pairs[0].kernel_m  # started several kernels off
    truth = np.linalg.inv(A) @ B
    assert translation_error_m(f.T_target_source, truth) < 0.2 * pairs[0].kernel_m
    poses["b"] = A @ f.T_target_source  # the adjustment agrees with the pair's fit
    assert adj._measure(None, pairs, clouds, poses, config, None, 2) == 0
    assert pairs[0].fit is f
    poses["b"] = off  # back where the fit started: it would repeat that fit
    assert adj._measure(None, pairs, clouds, poses, config, None, 3) == 0
    poses["b"] = B @ _pose(-0.1, 2, (-0.015, 0.01, -0.005))  # away from both: measured again
    assert adj._measure(None, pairs, clouds, poses, config, None, 4) == 1
    assert pairs[0].fit is not f


def test_a_later_run_recalls_the_kept_fits_and_measures_only_what_it_moved(tmp_path) -> None:
    """Each measured fit is kept beside the adjustment clouds: a later run (new pairs, the
    same clouds) recalls it with the pose it started from and measures nothing while the
    solution stays within the fit's kernel; a pair moved beyond it, or whose kept fit is
    damaged, is measured again."""
    from flexreg.survey import adjust as adj
    from flexreg.survey.c2c import fit_cache_path
    from flexreg.survey.config import SurveyConfig

    rng = np.random.default_rng(2)
    A, B = _pose(10, 2, (3.0, 2.5, 1.5)), _pose(-25, 2, (7.0, 5.5, 1.6))
    clouds = {
        "a": _box_cloud(tmp_path / "a.npz", A, rng),
        "b": _box_cloud(tmp_path / "b.npz", B, rng),
    }
    clouds["c"] = _box_cloud(tmp_path / "c.npz", B, rng)
    poses = {"a": A, "b": B, "c": B.copy()}
    config = SurveyConfig()

    def fresh() -> list:
        return [adj.Pair("a", "b", "link"), adj.Pair("a", "c", "overlap")]

    first = fresh()
    assert adj._recall(first, clouds, config) == 0
    assert adj._measure(None, first, clouds, poses, config, None, 1) == 2
    again = fresh()
    assert adj._recall(again, clouds, config) == 2
    assert adj._measure(None, again, clouds, poses, config, None, 1) == 0
    for old, new in zip(first, again, strict=True):
        np.testing.assert_array_equal(new.fit.T_target_source, old.fit.T_target_source)
        np.testing.assert_array_equal(new.fit.information, old.fit.information)
        assert new.fit.figures == old.fit.figures and new.kernel_m == old.kernel_m
    poses["b"] = B @ _pose(0.0, 2, (1.5 * again[0].kernel_m, 0.0, 0.0))
    with open(fit_cache_path(clouds["a"], clouds["c"]), "wb") as f:
        f.write(b"not a fit")
    later = fresh()
    assert adj._recall(later, clouds, config) == 1  # the damaged one is not recalled
    assert adj._measure(None, later, clouds, poses, config, None, 1) == 2


def test_cloud_to_cloud_pairs_only_normals_facing_the_same_side():
    """A wall's front face (target, normals towards its scanner: -x) and points 1 cm off it:
    seen by a source scanner on the same side (normals -x) they overlap; seen from behind
    the wall (normals +x: its back face) none does."""
    g = np.stack(np.meshgrid(np.linspace(0, 1, 11), np.linspace(0, 1, 11)), -1).reshape(-1, 2)
    tgt = np.column_stack([np.full(len(g), 3.0), g])
    n = np.tile([-1.0, 0.0, 0.0], (len(g), 1))
    src = tgt + [0.01, 0.0, 0.0]
    front = cloud_figures(tgt, n, src, np.eye(4), 0.05, src_n=n)
    back = cloud_figures(tgt, n, src, np.eye(4), 0.05, src_n=-n)
    assert front.overlap == 1.0 and abs(front.rms_mm - 10.0) < 1e-6
    assert back.overlap == 0.0 and back.points == 0 and back.rms_mm is None


def _two_rooms_cloud(path, T_world_scanner: np.ndarray, rng: np.random.Generator) -> str:
    """An adjustment cloud of two 5 x 4 x 3 m rooms either side of a 10 cm wall (x from 5
    to 5.1 m) with a 1 m doorway, seen from a scanner at ``T_world_scanner`` in one of them:
    its own room's faces, and through the doorway patches of the other room's floor, far
    wall and a side wall.
    Normals face the scanner; 1 mm noise along them."""
    step, mine = 0.04, T_world_scanner[0, 3] < 5.0

    def patch(axis, at, lo, hi, facing):
        u, v = np.meshgrid(np.arange(lo[0], hi[0], step), np.arange(lo[1], hi[1], step),
                           indexing="ij")  # fmt: skip
        p = np.insert(np.c_[u.ravel(), v.ravel()], axis, at, axis=1)
        n = np.zeros_like(p)
        n[:, axis] = facing
        return p, n

    x0, x1 = (0.0, 5.0) if mine else (5.1, 10.1)
    far, near = (10.1, 0.0) if mine else (0.0, 10.1)
    side = 1.0 if mine else -1.0  # the room's own wall at x0 faces +x in the first room
    faces = [
        patch(2, 0.0, (x0, 0), (x1, 4), 1.0),
        patch(1, 0.0, (x0, 0), (x1, 3), 1.0),
        patch(1, 4.0, (x0, 0), (x1, 3), -1.0),
        patch(0, near, (0, 0), (4, 3), side),
        patch(0, x1 if mine else x0, (0, 0), (1.5, 3), -side),  # the wall, but the doorway
        patch(0, x1 if mine else x0, (2.5, 0), (4, 3), -side),
        # through the doorway, the other room's floor, far wall and a side wall
        patch(
            2,
            0.0,
            (x1 + 0.1, 1.2) if mine else (0.0, 1.2),
            (10.1, 2.8) if mine else (x0 - 0.1, 2.8),
            1.0,
        ),
        patch(0, far, (0.8, 0), (3.2, 2.5), -side),
        patch(1, 4.0, (8.0, 0) if mine else (0.0, 0), (10.1, 3) if mine else (2.1, 3), -1.0),
    ]
    pts = np.vstack([p for p, _ in faces])
    nrm = np.vstack([n for _, n in faces])
    pts = pts + rng.normal(0, 0.001, pts.shape) * nrm
    inv = np.linalg.inv(T_world_scanner)
    p, n = pts @ inv[:3, :3].T + inv[:3, 3], nrm @ inv[:3, :3].T
    np.savez(str(path), points=p.astype(np.float32), normals=n.astype(np.float32),
             sparse=np.arange(0, len(p), 5), median_range_m=np.float64(3.0))  # fmt: skip
    return str(path)


def test_two_groups_fit_on_all_their_overlap_through_a_doorway(tmp_path) -> None:
    """Two stations in one room, one in the next: started from the right placement, or slid
    10 cm through the wall (the next room's wall face then lies on this room's, facing the
    other way: no pair joins them), the groups' fit comes within 5 mm and 0.05 deg of the
    truth, held by the far walls each side sees through the doorway."""
    from flexreg.core.transforms import rotation_error_deg, translation_error_m

    rng = np.random.default_rng(1)
    A1, A2 = _pose(20, 2, (2.0, 1.5, 1.5)), _pose(-40, 2, (3.5, 3.0, 1.4))
    B = _pose(70, 2, (7.5, 2.0, 1.6))
    a1 = _two_rooms_cloud(tmp_path / "a1.npz", A1, rng)
    a2 = _two_rooms_cloud(tmp_path / "a2.npz", A2, rng)
    b = _two_rooms_cloud(tmp_path / "b.npz", B, rng)
    target = [(a1, A1), (a2, A2)]  # the first group's frame: the world
    for slide in (0.0, -0.1):
        start = _pose(0.05, 2, (slide, 0.01, 0.0)) @ B
        X = fit_groups(target, [(b, np.eye(4))], start, 0.03)
        assert translation_error_m(X, B) < 0.005 and rotation_error_deg(X, B) < 0.05
    with pytest.raises(ValueError):
        fit_groups(target, [], B, 0.03)


def _pose_graph(weights):
    """A reference ``r`` and two stations ``a``, ``b`` 4 m apart along x, each pair measured
    exactly with information ``w * I`` (``weights``: per pair), the reference held by the
    final alignment's Gaussian prior."""
    import gtsam

    P = {"r": np.eye(4), "a": np.eye(4), "b": np.eye(4)}
    P["a"][0, 3], P["b"][0, 3] = 4.0, 8.0
    key = {"r": 0, "a": 1, "b": 2}
    g, v = gtsam.NonlinearFactorGraph(), gtsam.Values()
    for s, T in P.items():
        v.insert(key[s], gtsam.Pose3(T))
    g.add(
        gtsam.PriorFactorPose3(
            0, gtsam.Pose3(P["r"]), gtsam.noiseModel.Isotropic.Sigma(6, REF_SIGMA)
        )
    )
    for (t, s), w in weights.items():
        rel = gtsam.Pose3(np.linalg.inv(P[t]) @ P[s])
        g.add(
            gtsam.BetweenFactorPose3(
                key[t], key[s], rel, gtsam.noiseModel.Gaussian.Information(np.eye(6) * w)
            )
        )
    return g, v, key


def test_covariances_of_a_chain_hand_computed():
    """r -> a -> b, no rotation between them: a's covariance is the r-a pair's (1 / w), b's
    the sum of both pairs' (the reference's micron prior adds 1e-12); the dense inverse of the
    information matrix gives what gtsam's marginals give."""
    g, v, key = _pose_graph({("r", "a"): 1e4, ("a", "b"): 4e4})
    cov = covariances(g, v, key, "r")
    assert set(cov) == {"a", "b"}
    np.testing.assert_allclose(np.diag(cov["a"])[:3], 1e-4, rtol=1e-6)
    np.testing.assert_allclose(np.diag(cov["a"])[3:], 1e-4, rtol=1e-6)
    np.testing.assert_allclose(np.diag(cov["b"])[:3], 1.25e-4, rtol=1e-6)
    dense = _dense_covariances(g, v, key, "r")
    for s in ("a", "b"):
        np.testing.assert_allclose(dense[s], cov[s], rtol=1e-6, atol=1e-14)


def test_dense_covariances_of_a_loop_match_the_marginals():
    """A loop r-a-b-r of unequal weights: the dense path agrees with gtsam's marginals."""
    g, v, key = _pose_graph({("r", "a"): 1e4, ("a", "b"): 3e5, ("r", "b"): 2e3})
    marg, dense = covariances(g, v, key, "r"), _dense_covariances(g, v, key, "r")
    for s in ("a", "b"):
        np.testing.assert_allclose(dense[s], marg[s], rtol=1e-6, atol=1e-14)
        assert np.linalg.eigvalsh(dense[s])[0] > 0
