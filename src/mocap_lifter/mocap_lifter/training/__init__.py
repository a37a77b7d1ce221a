"""Training and evaluation of the lifter networks (``mocap train lifter|vtm``, ``mocap eval
lifter``): samples from the processed dataset, training loops, evaluation, the command line.
Nothing of the runtime (:mod:`mocap_lifter.node`, :mod:`mocap_lifter.online`) imports it."""
