"""GMR: world-frame global motion from the local pose sequence with a bidirectional GRU.

Runtime: :mod:`.model` (network), :mod:`.weights` (weights I/O), :mod:`.features`,
:mod:`.se3`, :mod:`.online` (streaming), :mod:`.node` (``ros2 run mocap_global gmr``),
:mod:`.bench`, :mod:`.bags`. Training and evaluation: :mod:`.training` (never imported by the
runtime). Layout and design: ``docs/global.md``.
"""

import os

# Idle OpenMP threads sleep instead of spinning; libgomp reads this when torch loads it, so it
# is set before any module of the package imports torch (docs/global.md, training section).
os.environ.setdefault('OMP_WAIT_POLICY', 'PASSIVE')
