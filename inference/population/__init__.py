"""The class as a population of drones: :mod:`.model` (the spreads' model, hyperprior
and hyper-posterior), :mod:`.result` (fit from calibrated drones, the file, new
drones) and :mod:`.augment` (population draws as an augmenter's source).
"""
