"""Controllers of the stage and their design."""
