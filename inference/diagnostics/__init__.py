"""Simulation-based calibration of the calibration: :mod:`.sbc` (the one resumable
replicate runner, ranks and their summary; SBC of the closed-form route) and
:mod:`.population_sbc` (SBC of the population's spreads) and :mod:`.sbc_figure` (the SBC figure of any
route: rank histograms and coverage curve). The amortized route's SBC
(:mod:`..amortized.sbc`) uses the same summary and figure.
"""
