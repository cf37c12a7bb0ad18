"""The building blocks of registration: functions over arrays and core types.

Each stage takes plain keyword arguments (never an application's config) and can be used
alone; :func:`flexreg.registration.register` composes them from its config.

=============  ==================================  ==================  =====================
stage          function (module.function)          input               output
=============  ==================================  ==================  =====================
range image    projection.working_image            Scan                RangeImage
holes          projection.fill_holes               RangeImage          RangeImage
gaps           projection.sampling_gaps            (H, W) bool         bool (no sensor grid)
viewpoint      viewpoint.hidden_share              (N, 3), origin      share hidden
               (choose_viewpoint: a virtual one)
feature image  feature_images.feature_image        RangeImage          (H, W) uint8, mask
               (convert, quantize: eq. 9-14)
keypoints      keypoints.detect_and_describe       uint8 image, mask   Features
matching       matching.match                      Features x 2        (Q, 2) index pairs
3D points      correspondences.lift                RangeImage, (K, 2)  (K, 3), lifted mask
threshold      correspondences.derive_threshold    images, keypoints   metres
RANSAC prior   alignment.ransac_rigid              (Q, 3) x 2          RansacResult
plan prior     priors.upright_priors               RangeImage x 2      list of (4, 4)
               (plan_view, plan_overlays;
               plan_correlation: the overlays'
               FFT and windowed correlations)
geometric      geometric.geometric_hypotheses      (N, 3) x 2          list of Hypothesis
               (describe: FPFH; hypotheses_from_
               matches: clique + RANSAC)
guided fit     alignment.guided_fit                prior, Features     GuidedFit
verification   verification.overlap_score          RangeImage x 2, T   consistent, conflict
               (classify_points, range_slack)
sampling       sampling.area_sample                (N, 3)              (M, 3)
normals        normals.grid_normals                RangeImage          (H, W, 3)
refinement     refinement.refine                   scans, coarse T     IcpResult
               (icp.refine_icp, projective_icp)
camera pose    camera_pose.solve_pnp               2D-3D pairs         PnPResult
=============  ==================================  ==================  =====================
"""
