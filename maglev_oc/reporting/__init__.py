"""Figures and PDF pages; takes result objects, never computes models."""
