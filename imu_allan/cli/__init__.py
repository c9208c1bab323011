"""Command-line entry points (analyze, discrepancy, gx3_sim)."""
