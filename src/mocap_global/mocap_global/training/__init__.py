"""Training and evaluation of GMR (``mocap train gmr``, ``mocap eval gmr``): training windows
(:mod:`.samples`), losses and the training loop (:mod:`.train`), metrics (:mod:`.metrics`),
the evaluation report (:mod:`.evaluate`) and the command line (:mod:`.cli`). The runtime
(network, weights, streaming, node) never imports this package."""
