"""The virtual experiments: quasi-static blocks, the servo, the loading paths and branches from
A, probing, records, resume, progress and cost, the runner
(:func:`~dem_taichi.protocol.runner.run_protocol`; ``python -m dem_taichi protocol``) and its
report (:mod:`~dem_taichi.protocol.report`).
"""

from dem_taichi._moved import forward_attributes

#: the names of the former module ``dem_taichi.protocol`` (now :mod:`dem_taichi.protocol.runner`)
__getattr__ = forward_attributes(__name__)
