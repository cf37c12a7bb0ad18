"""Optional multi-view refinement (``flexreg survey --refine``).

Open3D's multiway scheme, run on the accepted links only: each link is re-aligned by
point-to-plane ICP (Open3D) on voxel-downsampled clouds of its two stations, started from the
relative pose of the solved graph (so every link starts from the consensus of all the others,
not from its own pairwise answer), with the information matrix of the final correspondences;
then the pose graph is optimised again. ``refine_iterations`` rounds. Only the two clouds of
the link at hand are loaded (from the cache, on a worker), so memory does not grow with the
number of stations. It is not a simultaneous least-squares adjustment of every point pair of
every link; the pose graph with per-link information matrices is its usual approximation.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from numpy.typing import NDArray

from flexreg.core.scan import as_points
from flexreg.core.transforms import invert, rotation_error_deg, translation_error_m
from flexreg.survey.config import SurveyConfig
from flexreg.survey.execute import Progress, ProgressEvent, run_tasks
from flexreg.survey.graph import GraphSolution, Link
from flexreg.survey.stations import load_prepared


def _cloud(cache_file: str, voxel_m: float) -> Any:
    import open3d as o3d

    pts = as_points(load_prepared(cache_file).image)
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts)).voxel_down_sample(voxel_m)
    pcd.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=3 * voxel_m, max_nn=30))
    return pcd


def icp_link(
    target_file: str, source_file: str, T_init: NDArray[np.float64], voxel_m: float
) -> tuple[NDArray[np.float64], NDArray[np.float64], float]:
    """Point-to-plane ICP of one link on ``voxel_m`` clouds: ``T_target_source``, its 6x6
    information matrix (Open3D order) and the inlier RMSE, metres (runs on a worker)."""
    import open3d as o3d

    reg = o3d.pipelines.registration
    tgt, src = _cloud(target_file, voxel_m), _cloud(source_file, voxel_m)
    dist = 2.0 * voxel_m
    r = reg.registration_icp(
        src,
        tgt,
        dist,
        np.asarray(T_init, dtype=np.float64),
        reg.TransformationEstimationPointToPlane(),
        reg.ICPConvergenceCriteria(max_iteration=50),
    )
    T = np.asarray(r.transformation, dtype=np.float64)
    info = reg.get_information_matrix_from_point_clouds(src, tgt, dist, T)
    return T, np.asarray(info, dtype=np.float64), float(r.inlier_rmse)


def refine_links(
    client: Any,
    solution: GraphSolution,
    links: list[Link],
    files: dict[str, str],
    config: SurveyConfig,
    progress: Progress = None,
) -> int:
    """One round of ICP on every accepted link inside a solved group, in place (transform,
    information, RMSE); returns how many links were refined. A link whose ICP moves further
    than the loop tolerance from the solved relative pose keeps its pairwise answer. The
    caller re-solves the graph."""
    todo = [
        e
        for e in links
        if e.status == "accepted" and e.target in solution.poses and e.source in solution.poses
    ]
    t0 = time.perf_counter()
    done = [0]

    def report(_: int, __: Any) -> None:
        done[0] += 1
        if progress is not None:
            progress(
                ProgressEvent("refine", done[0], len(todo), elapsed_s=time.perf_counter() - t0)
            )

    items = [
        (
            files[e.target],
            files[e.source],
            invert(solution.poses[e.target]) @ solution.poses[e.source],
            config.refine_voxel_m,
        )
        for e in todo
    ]
    refined = 0
    for e, args, (T, info, rmse) in zip(
        todo, items, run_tasks(client, icp_link, items, on_result=report), strict=True
    ):
        moved = (rotation_error_deg(T, args[2]), translation_error_m(T, args[2]))
        if moved[0] > config.loop_max_deg or moved[1] > config.loop_max_m:
            continue  # ICP wandered off the consensus: keep the pairwise answer
        e.T_target_source, e.information, e.rmse_m = T, info, rmse
        refined += 1
    return refined


__all__ = ["icp_link", "refine_links"]
