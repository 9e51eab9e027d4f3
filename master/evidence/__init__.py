"""Evidence: reference solutions, error measures, the work-precision bench and stability analysis."""
