"""Motion-capture data pipeline (issue 3): BVH reading and retargeting to the pipeline skeleton,
motion processing, 2D synthesis, splits, the cached dataset and ground-truth bags.

Plain modules, no ROS imports (but :mod:`gt_bag`, which writes bags):

* :mod:`mocap_core.data.bvh` -- BVH parsing (any channel layout, end sites, CRLF, archives)
  and forward kinematics to world positions in metres, z up.
* :mod:`mocap_core.data.retarget` -- per-format joint maps and retargeting of a BVH clip to
  the fixed 18-joint skeleton (root position + local rotations relative to the T rest pose).
* :mod:`mocap_core.data.motion` -- resampling (slerp), floor height, foot contact labels.
* :mod:`mocap_core.data.synth2d` -- virtual cameras, 2D keypoints, detector-like corruption,
  flips, canonical keypoints.
* :mod:`mocap_core.data.splits` -- clip inventory and the deterministic train / validation
  split, committed as ``splits.json`` (:func:`~mocap_core.data.splits.load_splits`).
* :mod:`mocap_core.data.dataset` -- build and cache the processed dataset outside the
  repository, load it for training (:func:`~mocap_core.data.dataset.load_dataset`), report.
* :mod:`mocap_core.data.gt_bag` -- ground-truth bags from clips, keypoint bags from OpenPose
  JSON folders.
* :mod:`mocap_core.data.bvh_synth` -- a synthetic CMU-named BVH walk for tests without data.

Command line: ``mocap data build | report | split | to-bag | from-openpose | fit-confidence``.
"""
