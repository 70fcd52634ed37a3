"""The rig twin and closed-loop simulation."""
