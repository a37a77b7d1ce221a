"""MotioNet (and VTM) lifter: one symmetric skeleton, joint rotations, root position and foot
contacts from 2D keypoints. Layout: ``README.md`` of the package (runtime core and
``training/``)."""
