"""What is done with the model: CT-based prediction (:mod:`~arfi.analysis.prediction`), estimates
that start from it (:mod:`~arfi.analysis.prediction_estimate`, :mod:`~arfi.analysis.prior_modes`),
the paper's loop 2 (:mod:`~arfi.analysis.loop`), model-discrepancy diagnosis
(:mod:`~arfi.analysis.diagnose`), the focal region and safety lines (:mod:`~arfi.analysis.focal`,
:mod:`~arfi.analysis.safety`), and the studies: the paper's (:mod:`~arfi.analysis.reproduce`,
:mod:`~arfi.analysis.ladder`) and Monte-Carlo sweeps (:mod:`~arfi.analysis.sweep`)."""
