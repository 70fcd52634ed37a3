"""Stand-in analyses for the report runner's tests (the real ones take minutes)."""
