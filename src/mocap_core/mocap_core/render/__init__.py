"""Rendered people with exact ground truth, for training and benchmarking (no ROS imports).

Data generation, never runtime: no node imports this package (``test/test_layout.py``).

* :mod:`.body` -- an Anny body (``anny``, MakeHuman assets) driven by a pipeline motion, and
  the 18 pipeline joints of that body;
* :mod:`.scene` -- CPU rendering with pyrender (OSMesa): clothing colours, floor, background,
  lights;
* :mod:`.cameras` -- static, panning, orbiting, hand-held and following camera paths;
* :mod:`.clip` -- one clip end to end (video, detector keypoints, ground truth), and the
  resumable batch behind ``mocap data render``.

Anny, pyrender and the OSMesa library are optional: without them,
:class:`RendererUnavailable` says what is missing.
"""


class RendererUnavailable(RuntimeError):
    """The body model or the renderer cannot be loaded (the message says what to install)."""
