"""Parameter identification of the lumped constants C1..C4 (000 Sec. IV) and the papers'
verification procedures (000 Sec. V, 002 Sec. 5).

Modules
-------
(terms: AccelerationTerm lives in maglev_oc.regression, the layer identify and diagnose share)
layout           which parameters a fit estimates; the model's accelerations as a function of them
equation_error   filtered equation-error NLS (linear in C; exact Jacobians otherwise)
output_error     multiple-shooting output-error NLS (constrained Gauss-Newton)
npfsi            the reduced-order NPFSI estimator (000 eq. (3), 002 sidebar)
(covariance: maglev_oc.regression.covariance)
result           FitResult, NpfsiResult
verification     parabolas vs NPFSI, equilibrium currents, the cogging procedure
experiments      twin runs that produce the logs of the papers' experiments
pipeline         checks and all methods on log files (``maglev-oc identify``)
study            the whole twin study behind reports/identification.pdf
"""

from maglev_oc.identification.equation_error import EquationError, fit_equation_error
from maglev_oc.identification.npfsi import NpfsiEstimator, npfsi
from maglev_oc.identification.output_error import MultipleShooting, fit_output_error
from maglev_oc.identification.pipeline import IdentificationOutcome, identify, load_logs
from maglev_oc.identification.result import FitResult, NpfsiResult
from maglev_oc.regression.terms import AccelerationTerm

__all__ = [
    "AccelerationTerm",
    "EquationError",
    "FitResult",
    "IdentificationOutcome",
    "MultipleShooting",
    "NpfsiEstimator",
    "NpfsiResult",
    "fit_equation_error",
    "fit_output_error",
    "identify",
    "load_logs",
    "npfsi",
]
