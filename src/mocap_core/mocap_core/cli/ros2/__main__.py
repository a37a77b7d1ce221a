"""``python -m mocap_core.cli.ros2 ...``: the ``ros2`` command (see the package docstring)."""

import sys

from . import main

sys.exit(main())
