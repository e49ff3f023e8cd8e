"""The march checked against solvers it does not share code with: the suite of ``arfi validate``
(:mod:`~arfi.validation.suite`: exact solutions), the full-wave engine BabelViscoFDTD
(:mod:`~arfi.validation.fdtd`), and the stored full-wave results for textured skull caps
(:mod:`~arfi.validation.textured_caps`, :mod:`~arfi.validation.fullwave_caps`) and the head
phantom (:mod:`~arfi.validation.fullwave_head`)."""
