"""The lifter's accuracy and plausibility metrics: they live in :mod:`mocap_core.pose_metrics`
(shared with the pipeline reports); re-exported here for the lifter's evaluation."""

from mocap_core.pose_metrics import (accel_error_mm, bone_length_spread_mm,  # noqa: F401
                                     bone_lengths, contact_accuracy, foot_skating_mm, jitter_mm,
                                     mble_mm, mpjpe_mm, mrpe_mm, n_mpjpe_mm, pa_mpjpe_mm,
                                     procrustes_align)
