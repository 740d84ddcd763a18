"""The constrained family: the coupled (linear) and nonlinear (co-rotational) models, the rigid and elastic unknowns in one pass with the constraint rows."""
