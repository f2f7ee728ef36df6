"""The calibration's likelihoods, one module each over one base.

:mod:`.base` (the interface every likelihood gives the fit and the samplers, the
marginal likelihoods' shared checks, and :func:`~.base.prepare_measured`, the check and
normalisation of measured profiles every route starts from); :mod:`.fitted_phases`
(the phases fitted: the published single chirp, K = 1); :mod:`.closed_form` (the
phases marginalised in closed form, measured K >= 1); :mod:`.synthetic` (the phases
marginalised by simulation). Imports :mod:`..space` for the layout.
"""
