"""Core library of the monocular motion-capture pipeline: skeleton, rotations, forward
kinematics, URDF, ROS message conversions, QoS, diagnostics, bag I/O, the failure policy, the
plugin registry and the ros2/mocap command-line tools. No node; imports no node package."""
