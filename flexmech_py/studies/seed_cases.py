"""The seed paper's cases (Hac, Sec. 4) and the differences between models the seed report quotes."""

from __future__ import annotations

import numpy as np

__all__ = ["SEED_CASES", "ALLOYS", "model_differences", "load_vector_difference"]

SEED_CASES = ("fourbar_hac", "fourbar_constant_speed", "manipulator_bricout", "manipulator_bricout_no_payload")
#: yield strength and Young's modulus [Pa] of two structural aluminium alloys (ASM Handbook Vol. 2 values:
#: 6061-T6 276 MPa, 68.9 GPa; 7075-T6 503 MPa, 71.7 GPa): the seed gives E = 71 GPa and no alloy
ALLOYS = {"6061-T6": (276e6, 68.9e9), "7075-T6": (503e6, 71.7e9)}


def _rel_peak(a: np.ndarray, b: np.ndarray) -> float:
    """max |a - b| / max |b|."""
    return float(np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-300))


def model_differences(results: dict, columns, ref: str = "classic") -> dict:
    """{model: {column: max|model - ref| / max|ref|}} over the given columns."""
    return {m: {c: _rel_peak(r.columns[c], results[ref].columns[c]) for c in columns}
            for m, r in results.items() if m != ref}


def load_vector_difference(results: dict, a: str, b: str) -> dict:
    """Difference of the rigid-inertia force vectors of models a and b (free translational DOFs), along the run."""
    r = results[a]
    free = r.fe.free_translational()
    fa = r.fe.loads(r.rig, a)[free]
    fb = r.fe.loads(r.rig, b)[free]
    nb = np.linalg.norm(fb, axis=0)
    d = np.linalg.norm(fb - fa, axis=0)
    return {"max_norm_diff_over_max_norm": float(d.max() / nb.max()),
            "max_componentwise_diff_over_max_component": float(np.max(np.abs(fb - fa)) / np.max(np.abs(fb))),
            "rms_norm_diff_over_rms_norm": float(np.sqrt(np.mean(d ** 2) / np.mean(nb ** 2))),
            "diff_norm": d, "norm_b": nb}
