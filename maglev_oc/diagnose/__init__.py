"""Close the loop with measured data: find what the model misses in a log and add it."""
