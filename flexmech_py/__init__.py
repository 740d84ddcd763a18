"""flexmech: finite-element dynamics of flexible planar mechanisms (kineto-elastodynamics).

Python API::

    import flexmech_py as fm
    case = fm.load_case("cases/fourbar_hac.toml")
    res = fm.simulate(case, model="hac")        # or "classic", "classic-translational", "coupled"
    res.t, res["strain_coupler_mid"]            # numpy arrays
    res.write("out/")                           # timeseries.csv, summary.json

The compiled kernels are in :mod:`flexmech_py.kernels`.
"""

__version__ = "0.1.0"

from .case import MODELS, SUPERPOSITION_MODELS, Case, apply_overrides, load_case, validate_case  # noqa: E402
from .errors import CaseError, FlexmechError, MechanismError, SolverError  # noqa: E402
from .mechanism import Mechanism  # noqa: E402
from .simulate import simulate  # noqa: E402

__all__ = ["load_case", "validate_case", "apply_overrides", "simulate", "Case", "Mechanism", "MODELS",
           "SUPERPOSITION_MODELS", "FlexmechError", "CaseError", "MechanismError", "SolverError", "__version__"]
