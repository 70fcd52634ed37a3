"""The stage model: parameters, magnetic factors, the CasADi state equation and what follows from it."""
