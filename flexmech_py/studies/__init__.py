"""Studies: many runs compared (accuracy, sweeps, sampling, compare, modes, stability, the seed report, benchmarks, shaping, design studies and optimization)."""
