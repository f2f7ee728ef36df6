"""The summary likelihood of the smc route: :mod:`.summary` (the folded mean
log-profile and its whitening), :mod:`.sketch` (where a drone's lines put power, in
closed form), :mod:`.net` (the emulator, the within-drone covariance and the
emulator-error networks), :mod:`.model` (the trained model, its Fisher information and
Cramer-Rao bound, its file parts), :mod:`.posterior` (prior x summary likelihood in the
label-free coordinates) and :mod:`.train` (training it from simulated drones).
"""
