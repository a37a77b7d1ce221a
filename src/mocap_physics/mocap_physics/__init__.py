"""Physics cycle of neural PhysCap on Pinocchio: PD control, ground reaction forces in friction cones, forward dynamics, no-penetration QP."""
