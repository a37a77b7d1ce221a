"""Training and evaluation of the physics stage (not imported by the node).

* :mod:`.train_dynet`: the differentiable rollout of the cycle and the DyNet training loop
  (``mocap train physics``);
* :mod:`.evaluate`: the cycle on ground-truth motion, clean or with lifter-like noise, and
  its metrics and report (``mocap eval physics``);
* :mod:`.cli`: the ``mocap train|eval physics`` subcommands.
"""
