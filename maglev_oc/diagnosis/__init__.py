"""Close the loop with measured data: find what the model misses in a log and add it.

Modules
-------
pipeline     ``diagnose``: the whole procedure, as named steps
result       Diagnosis, Effect, NotSeparable: what it found (the SPEC 3 JSON via ``to_dict()``)
candidate    Candidate (one effect: term, plausibility, finding) and the library's context
library      the candidate effects of linear-guide PMLSM stages, assembled from
             guides (friction, misalignment, waviness, cable carrier, tilt), magnetics (cogging,
             detent, end effects, field shape), currents (ripple, commutation, amplifier lag)
probes       generic smooth functions: the rivals a named effect must beat
selection    each candidate judged in a joint fit with C1..C4; forward selection, backward check
unexplained  residual structure that no candidate explains, with its signature
refit        the refitted model and constants, reference convergence of bilinear terms
prediction   short-horizon output error of a model on held-out data
trace        what the residual depends on (spatial spectrum, binned dependences, lags)
feedback     what a found effect is worth in control (FL regulator with it compensated)
"""

from maglev_oc.diagnosis.pipeline import Diagnosis, Effect, NotSeparable, diagnose
from maglev_oc.diagnosis.unexplained import Unexplained

__all__ = ["Diagnosis", "Effect", "NotSeparable", "Unexplained", "diagnose"]
