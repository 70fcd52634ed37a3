"""The one equation-error regression layer that identify and diagnose share.

Modules
-------
data        logs prepared for a filtered equation-error fit: rate, derivatives, the matching
            filter, the logged currents' errors, masks (:func:`prepare`)
terms       AccelerationTerm: an extra acceleration with its own parameters, and the physical
            terms both layers use (friction, constant forces, cogging)
base        names, units and axes of the base model's parameters (C1..C4, gap offset)
design      columns, target and their Gram matrices per block of samples (:func:`build_design`)
solve       subset fits, the long-run covariance, Gauss-Newton for nonlinear parameters
covariance  the long-run (HAC) covariance of an estimate from autocorrelated residuals
noise_scale the scale of the logged currents' errors at which two bands agree on the constants
payload     a payload a log declares: its forces read as the unloaded stage's, and simulated
            moving the loaded one
stoppers    stretches where a stop, not the magnets, holds the stage
"""

from maglev_oc.regression.data import PreparedLogs, prepare
from maglev_oc.regression.design import Design, build_design
from maglev_oc.regression.solve import SubsetFit, fit_nonlinear, fit_subset
from maglev_oc.regression.terms import AccelerationTerm, Estimate

__all__ = [
    "AccelerationTerm",
    "Design",
    "Estimate",
    "PreparedLogs",
    "SubsetFit",
    "build_design",
    "fit_nonlinear",
    "fit_subset",
    "prepare",
]
