"""Operating region of the controllers: where the FL regulator's feedback transformation stays defined.

* :mod:`~maglev_oc.region.closed_loop` — the FL loop in error coordinates with its exosystem
  (:class:`Reference`, :class:`RegulatorLoop`).
* :mod:`~maglev_oc.region.feasibility` — the feasible set F (R >= 0, |u| <= 9 A, stoppers) and its
  maps with exact boundaries (:class:`FeasibleSet`, :func:`feasibility_map`).
* :mod:`~maglev_oc.region.interval` — interval arithmetic over CasADi graphs (:class:`IntervalFunction`).
* :mod:`~maglev_oc.region.procedure2` — Procedure 2 of Maggiore & Becerril adapted and certified
  (:class:`Procedure2`), from its parts: :mod:`~maglev_oc.region.ellipsoid` (level sets and the
  initial conditions they hold), :mod:`~maglev_oc.region.branch_and_bound` (the certificate) and
  :mod:`~maglev_oc.region.boundary` (IPOPT's upper bounds).
* :mod:`~maglev_oc.region.sdp` — P chosen by SDP over a proved inner polytope (:func:`enlarge`).
* :mod:`~maglev_oc.region.roa` — regions of attraction of the linear regulators (:func:`certify_roa`).
* :mod:`~maglev_oc.region.montecarlo` — vectorised runs of the sampled twin (:class:`BatchSimulator`).
* :mod:`~maglev_oc.region.study` — everything the report shows (:func:`operating_region_study`).
* :mod:`~maglev_oc.region.sweep` — Monte Carlo over sampled plants (the constants from a confidence
  set or a box, the controller nominal) as Dask tasks, the same numbers on any number of workers.
* :mod:`~maglev_oc.region.robust` — what the nominal certificate is worth on those plants
  (sampled, never certified): feasible shares by confidence level, where runs first leave F.
* :mod:`~maglev_oc.region.robust_certificate` — a level set certified forward invariant in F for
  every plant of a box or confidence ellipsoid (:class:`RobustCertifier`, interval branch and bound).
"""

from maglev_oc.region.closed_loop import Reference, RegulatorLoop
from maglev_oc.region.feasibility import FeasibilityMap, FeasibleSet, feasibility_map
from maglev_oc.region.interval import IntervalFunction
from maglev_oc.region.montecarlo import (
    BatchSimulator,
    CertificateCheck,
    SliceCheck,
    check_error_states,
    fl_slice,
    uniform_in_ellipsoid,
)
from maglev_oc.region.procedure2 import Procedure2, Procedure2Result
from maglev_oc.region.roa import LinearizedLoop, RoaResult, certify_roa
from maglev_oc.region.robust_certificate import (
    RobustCertificate,
    RobustCertifier,
    certify_robust,
    robust_lyapunov_matrix,
)
from maglev_oc.region.sdp import SdpResult, enlarge
from maglev_oc.region.study import OperatingRegionStudy, StudyConfig, operating_region_study

__all__ = [
    "BatchSimulator",
    "CertificateCheck",
    "FeasibilityMap",
    "FeasibleSet",
    "IntervalFunction",
    "LinearizedLoop",
    "OperatingRegionStudy",
    "Procedure2",
    "Procedure2Result",
    "Reference",
    "RegulatorLoop",
    "RoaResult",
    "RobustCertificate",
    "RobustCertifier",
    "SdpResult",
    "SliceCheck",
    "StudyConfig",
    "certify_roa",
    "certify_robust",
    "check_error_states",
    "enlarge",
    "feasibility_map",
    "fl_slice",
    "operating_region_study",
    "robust_lyapunov_matrix",
    "uniform_in_ellipsoid",
]
