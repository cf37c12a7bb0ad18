"""Register a whole project of N stations: ``flexreg survey``.

The flow (one module per step):

``stations``  find the scan files, prepare each station once
              (:meth:`flexreg.registration.Registration.prepare`) and cache it in
              ``DIR/cache/`` keyed by file content and configuration, with a compact global
              descriptor per station for place recognition;
``pairs``     choose the candidate links (place recognition + file-order neighbours, or all,
              or sequential, or a CSV of ``target,source``);
``execute``   run preparation and links on Dask (a local cluster, or an existing one by
              scheduler address); the same link gives the same result on any worker;
``graph``     spanning tree of the strongest confident (or vouched) links, loop-closure
              checks, robust pose-graph optimisation (Open3D's line process), connected
              groups; ``links`` holds a link with its alternatives, ``positions`` the rough
              positions that pick between them;
``adjust``    the final joint alignment: every placed station refined on its overlapping
              points (cloud to cloud), its 1-sigma accuracy and status;
``outputs``   poses.json, stations/STEM.txt, merged PLY, E57 (all atomic);
``project``   :func:`run_survey`, the one call that does all of the above.

Public API
----------
``SurveyConfig``                          every knob (with a nested ``registration``:
                                          :class:`~flexreg.registration.RegistrationConfig`)
``find_scans(paths) -> list[Path]``       the scan files of files and folders, sorted
``run_survey(paths, out_dir, config, *, workers=None, scheduler=None, reference=None,
pairs_file=None, add_pairs=False, links=None, origins_file=None, positions_file=None,
frame="reference", progress=None) -> SurveyResult``
                                          the whole project; writes only ``out_dir/cache/``
``SurveyResult.to_dict() -> dict``        the poses document below (what poses.json holds)
``write_outputs(result, out_dir, *, merged=None, voxel_m=0.02, e57=None) -> list[Path]``
                                          poses.json, stations/, report.html, merged PLY, E57
``solve_graph(stations, links, config, *, reference=None) -> GraphSolution``
                                          the pose-graph step alone (hand-built graphs)
``Link``                                  one attempted link (input and output of the graph)
``evaluate(poses_doc, gt) -> dict``       per-station error against a ``flexreg synth`` gt.json

poses.json (schema version 1)
-----------------------------
All transforms are 4x4 row-major float lists; ``T_a_b`` maps points of b's scanner frame into
a's frame. Angles in degrees, distances in metres, overlaps as fractions 0..1. ``null`` where a
value does not exist (failed link, unplaced station)::

    {
      "schema": "flexreg.survey/1",
      "flexreg_version": "0.1.0",
      "reference": "station_00",             # STEM of the frame every pose is given in
                                             # (--reference, else the first by name of the
                                             # largest group)
      "frame": {"kind": "reference",         # reference | stored | origins (survey/frames.py)
                "site": "the frame of station station_00",
                "T_site_reference": [[...]]},
      "stations": {
        "station_00": {
          "file": "scans/station_00.ptx",    # as given on the command line
          "points": 421234,                  # valid returns (null: unreadable)
          "placed": true,                    # pose known in the reference frame
          "T_reference_station": [[...]],    # 4x4 or null (unplaced)
          "group": 0,                        # connected group id (0: the reference's group);
                                             # null for an unreadable station
          "group_reference": "station_03",   # the station whose frame the group is solved in
          "T_group_station": [[...]],        # pose in the group's frame (also when the group
                                             # is not the reference's: nothing is lost)
          "degree": 3,                       # accepted links at this station
          "links_attempted": 5,
          "confidence": "confident",         # "confident": placed through confident links
                                             # that close loops; "single": so, but through
                                             # a confident link that closes no loop (status
                                             # "placed"); "uncertain": only
                                             # loop-confirmed uncertain links hold it;
                                             # null: unplaced
          "reason": null,                    # unplaced: why, in words
          "error": null,                     # unreadable: the one-line error
          "status": "verified",              # verified | placed | outside_tolerance | unplaced
          "status_why": null,                # why not verified, in words
          "accuracy": {"sigma_deg": {"roll": 0.001, "pitch": 0.001, "yaw": 0.002},
                       "sigma_mm": {"x": 0.4, "y": 0.5, "z": 0.3},   # 1 sigma, reference axes
                       "radius95_mm": 1.4, "rotation95_mm": 0.6,     # null: unknown
                       "checked": true},             # false (status "placed"): nothing
                                                     # but the links it rests on fixes
                                                     # it, and the sigma does not cover
                                                     # a wrong one
          "origin": null,                    # --origins: scanner position in the file, m
          "T_site_station": [[...]],         # the pose in the site frame (float64)
          "T_site_file": [[...]]             # the file's correction (stations/STEM.txt)
        }, ...
      },
      "groups": [
        {"id": 0, "reference": "station_03", "stations": ["station_00", ...], "placed": true},
        {"id": 1, "reference": "station_09", "stations": ["station_09", "station_10"],
         "placed": false}
      ],
      "links": [
        {
          "target": "station_00", "source": "station_01",
          "origin": "sequential",            # why it was tried: sequential | place | proximity
                                             # | all | file | hand (--link)
          "place_score": 0.41,               # place-recognition score (null: not ranked)
          "status": "accepted",              # accepted | rejected | failed
          "why": null,                       # rejected / failed: the reason in words
          "T_target_source": [[...]],        # the pairwise result (null: failed)
          "verdict": "confident",            # confident | uncertain | null (failed)
          "reasons": [{"code": "low_overlap", "message": "..."}],
          "overlap": 0.61,                   # as register and compare state it:
          "overlap_of": "of 18,204 source points within 9.1 cm of a target point ...",
          "open3d_fitness": 0.61,            # Open3D's evaluate_registration, same clouds
          "open3d_inlier_rmse_m": 0.041,
          "overlap_target": 0.58, "overlap_source": 0.57,  # view-consistency (verdict)
          "matches": 211, "inliers": 52,     # inliers of the matched keypoint pairs
          "rmse_m": 0.0117, "fitness": 0.255,  # the final stage's own (ICP) figures
          "strength": {"roll": 0.24, "pitch": 0.31, "yaw": 0.18,
                       "x": 0.20, "y": 0.20, "z": 0.59},
          "information": [[...]],            # 6x6, (rx, ry, rz, tx, ty, tz), Open3D order
          "in_tree": true,                   # it merged two groups (survey/consensus.py)
          "confirmed_by_loop": true,         # a closed loop agrees with it
          "map_joined": false,               # joined two groups at the one placement of
                                             # several the map allows (survey/consensus.py)
          "repeat": false,                   # ambiguous: the answer moved a whole bay fits
                                             # too (registration/twins.py)
          "loop_error_deg": 0.01,            # accepted: disagreement with the final poses;
          "loop_error_m": 0.002,             # rejected: with the loop it closes; null: none
          "seconds": 3.8,                    # wall time of the pairwise registration
          "cached": false,                   # read from DIR/cache/links/ (an earlier run)
          "alternatives": [{"T_target_source": [[...]], "kind": "twin", "support": 0.8}],
                                             # other poses that fit: runner_up | twin | answer
          "vouched": null,                   # hand | positions: trusted beyond its verdict
          "picked": null,                    # what picked an alternative over the answer
          "refused": null,                   # why rough positions refused every pose
          "loop_error": "unchecked",         # only when accepted and it closes no loop
          "cloud_to_cloud": {"rms_mm": 3.1, "within_6mm": 0.93, "within_1cm": 0.97,
                             "overlap": 0.41, "balance": 0.3, "points": 18000,
                             "source_points": 40000},     # after the final alignment
          "link_error": {"deg": 0.002, "mm": 0.4}   # or "unchecked" (closes no loop)
        }, ...
      ],
      "summary": {
        "stations": 8, "readable": 8, "placed": 8,
        "unplaced": [],                      # STEMs
        "groups": 1,
        "links_attempted": 20, "links_accepted": 14, "links_rejected": 4, "links_failed": 2,
        "bundle_error_m": 0.0004,            # RMS translation residual of the final
        "bundle_error_deg": 0.003,           # alignment's pairs that close loops
        "mean_link_error_m": 0.002, "max_link_error_m": 0.006,
        "mean_link_error_deg": 0.008, "max_link_error_deg": 0.03,
        "bundle_of": "12 cloud-to-cloud pairs that close loops (2 unchecked)",
        "refined": true,                     # the final joint alignment ran
        "statuses": {"verified": 7, "placed": 0, "outside_tolerance": 0, "unplaced": 1},
        "status_line": "7 verified, 0 placed, 0 outside tolerance, 1 unplaced",
        "tolerance_mm": 10.0,
        "exit_status": 0,                    # 0 all verified, 3 not, 1 nothing placed
        "problems": ["station_07: unplaced (no accepted link)"],   # one line each
        "wall_s": 95.2,
        "timings_s": {"prepare": 60.1, "read_sum": 40.3, "prepare_sum": 78.9,
                      "pairs": 0.4, "links": 30.2, "graph": 0.3, "map_check": 4.1,
                      "refine": 12.0},                # wall s per stage; *_sum: per station
        "workers": 2,
        "prepared": 8, "from_cache": 0,      # stations prepared now / read from the cache
        "links_from_cache": 0                # links read from the cache
      },
      "final_alignment": {"rounds": 2, "settled": true, "pairs": 14, "pairs_measured": 14,
                          "pairs_checked": 12, "pairs_unchecked": 2, "pairs_left_out": 0,
                          "bundle_error_mm": 0.4, "bundle_error_deg": 0.003,
                          "variance_factor": 0.5, "redundancy": 30, "seconds": 20.1,
                          "pair_list": [...]},    # null with --no-refine
      "config": {...}                        # SurveyConfig.to_dict() (registration nested)
    }
"""

from flexreg.exports import lazy

#: public name -> the module that defines it (loaded on first use: see flexreg.exports)
_WHERE = {
    "GraphSolution": "flexreg.survey.graph",
    "Link": "flexreg.survey.graph",
    "SurveyConfig": "flexreg.survey.config",
    "SurveyResult": "flexreg.survey.project",
    "evaluate": "flexreg.survey.outputs",
    "find_scans": "flexreg.survey.stations",
    "run_survey": "flexreg.survey.project",
    "solve_graph": "flexreg.survey.graph",
    "write_outputs": "flexreg.survey.outputs",
}
__getattr__, __dir__ = lazy(globals(), _WHERE)
__all__ = list(_WHERE)
