"""Simulation-based calibration of the calibration: :mod:`.sbc` (the one resumable
replicate runner, ranks and their summary; SBC of the closed-form route) and
:mod:`.routes` (SBC of any posterior route on fresh simulated drones: ranks, coverage
curve, widths, TARP; the amortized estimators' SBC), :mod:`.population_sbc` (SBC of
the population's spreads) and :mod:`.sbc_figure` (the SBC figure of any route: rank
histograms and coverage curve); :mod:`.yardsticks` (beside SBC: the log score of the
truth; the gate is :func:`mdaug.inference.result.status.honest`) and the route table in
:mod:`.routes`.
"""
