"""Motion-capture data pipeline (issue 3): BVH reading and retargeting to the pipeline skeleton.

Plain modules, no ROS imports:

* :mod:`mocap_core.data.bvh` -- BVH parsing (any channel layout, end sites, CRLF, archives)
  and forward kinematics to world positions in metres, z up.
* :mod:`mocap_core.data.retarget` -- per-format joint maps and retargeting of a BVH clip to
  the fixed 18-joint skeleton (root position + local rotations relative to the T rest pose).
"""
