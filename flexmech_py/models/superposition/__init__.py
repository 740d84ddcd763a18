"""The superposition family: elastic deflection on a rigid-body motion computed first (hac, hac-case2, classic, classic-translational)."""
