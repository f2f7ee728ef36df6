"""Amortized calibration: simulation-based inference trained on mdaug's own simulator.

Rooms: :mod:`.target` (the label-free quantities, their coordinates, the prior's
density there, the drone space truths are drawn in); :mod:`.simulate` (training
drones through the scene simulator and the chain, in resumable shards); :mod:`.nets`
and :mod:`.train` (sbi's flow over a permutation-invariant embedding, the ratio
network, the resumable training loop); :mod:`.estimator` (the trained estimator as a
checked file; training one is a job one floor up, :mod:`..estimator_job`, ending
with its SBC from :mod:`..diagnostics`); :mod:`.ratio_posterior` (the ratio network's
posterior) and :mod:`.tempered` (tempered SMC from the amortized posterior to a
learned likelihood's posterior); :mod:`.calibrate` (one drone -> a CalibrationResult); :mod:`.shipped`
(the estimators in ``data/``). Imports :mod:`mdaug.generator`, :mod:`mdaug.radar` and
the inference rooms below it (space, likelihood preparation, the SMC engine,
result). torch loads with :mod:`.nets`, :mod:`.train` and :mod:`.estimator`
(not with :mod:`mdaug.inference`), sbi inside the functions that build networks.
"""
