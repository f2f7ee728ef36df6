"""The parameter space the calibration samples: :mod:`.priors` (the class's prior box,
line labels and engine lines), :mod:`.layout` (the flat coordinates theta of a
likelihood: shared class vector, per-measurement terms, bounds, relabelling) and
:mod:`.line_layout` (the layout in line space). Imports :mod:`mdaug.generator` only.
"""
