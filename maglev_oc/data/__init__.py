"""Logs of measured or simulated runs: reading, validating, writing (SPEC 2)."""
