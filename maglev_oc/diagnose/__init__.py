"""Close the loop with measured data: find what the model misses in a log and add it.

Modules
-------
library      the candidate effects of linear-guide PMLSM stages (Candidate), generic probes
selection    each candidate judged in a joint fit with C1..C4; forward selection, backward check
unexplained  residual structure that no candidate explains, with its signature
trace        what the residual depends on (spatial spectrum, binned dependences, lags)
diagnosis    ``diagnose``: the whole procedure and its result (the SPEC 3 JSON)
feedback     what a found effect is worth in control (FL regulator with it compensated)
"""

from maglev_oc.diagnose.diagnosis import Diagnosis, Effect, NotSeparable, diagnose
from maglev_oc.diagnose.unexplained import Unexplained

__all__ = ["Diagnosis", "Effect", "NotSeparable", "Unexplained", "diagnose"]
