"""A calibration's result: :mod:`.posterior` (:class:`~.posterior.CalibrationResult`,
arviz InferenceData saved as NetCDF), :mod:`.plots` (corner and trace), :mod:`.report`
(its text) and :mod:`.augment` (posterior draws as an augmenter's source).
"""
