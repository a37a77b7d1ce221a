"""Physics stage of the pipeline: neural PhysCap's dynamic cycle on Pinocchio.

PD control, ground reaction forces in friction cones, forward dynamics, no-penetration QP.
Runtime modules (the node imports only these) sit at the top level; training and evaluation
are in :mod:`mocap_physics.training` (see ``README.md`` of the package).
"""
