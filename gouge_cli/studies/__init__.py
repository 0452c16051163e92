"""Studies: measure the code (error against run time, speed against peers, analytic cases)."""
