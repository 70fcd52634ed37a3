"""Unit conversions, named by their direction: multiply a value in the left unit to get the right.

SI units everywhere inside maglev_oc; millimetres and micrometres only at the edges (reports,
command-line options, messages).
"""

__all__ = ["MM_TO_M", "M_TO_MM", "M_TO_UM"]

M_TO_MM = 1e3
"""metres -> millimetres"""
MM_TO_M = 1e-3
"""millimetres -> metres"""
M_TO_UM = 1e6
"""metres -> micrometres"""
