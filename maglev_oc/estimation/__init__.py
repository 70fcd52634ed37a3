"""State estimation: high-gain observers and differentiators."""
