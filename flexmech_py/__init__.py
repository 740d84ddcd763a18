"""flexmech: finite-element dynamics of flexible planar mechanisms (kineto-elastodynamics).

Python API::

    import flexmech_py as fm
    case = fm.load_case("cases/fourbar_hac.toml")   # a file here, else the bundled case of that name
    res = fm.simulate(case, model="hac")        # or "classic", "classic-translational", "coupled", "nonlinear"
    res.t, res["strain_coupler_mid"]            # numpy arrays
    res.write("out/")                           # timeseries.csv, summary.json

A run's warnings (``res.extra["warnings"]``) are issued as Python warnings of the classes
``fm.ValidityWarning``, ``fm.AccuracyWarning``, ``fm.MechanismWarning``, ``fm.StabilityWarning``
(all ``fm.FlexmechWarning``, a ``UserWarning``): filter them with :mod:`warnings`.

The bundled cases: ``fm.case_names()``, ``fm.case_path("fourbar_hac")``.  The compiled kernels are
in :mod:`flexmech_py.base.kernels`.
"""

import sys as _sys
from importlib import machinery as _machinery
from pathlib import Path as _Path


def _installed_instead():
    """When Python imports this package from the source tree (``python`` started in the repository
    root puts the folder on sys.path first), the compiled kernels are not here: load the installed
    package instead, which replaces this module in sys.modules.  Returns it, or None (this is it)."""
    here = _Path(__file__).resolve().parent
    if any(p.name.endswith(tuple(_machinery.EXTENSION_SUFFIXES)) for p in here.glob("_flexmech*")):   # kernels here
        return None
    elsewhere = [p for p in _sys.path if (_Path(p or ".") / __name__).resolve() != here]
    spec = _machinery.PathFinder.find_spec(__name__, elsewhere)
    if spec is None or spec.origin is None or _Path(spec.origin).resolve().parent == here:
        return None   # nothing installed: kernels.py says how to build
    import importlib.util

    module = importlib.util.module_from_spec(spec)
    _sys.modules[__name__] = module
    spec.loader.exec_module(module)
    return module


_installed_instead()   # after a handover the imports below find the installed modules, already loaded
from .base.version import __version__  # noqa: E402

from .base.bundled import case_names, case_path  # noqa: E402
from .case import Case, apply_overrides, load_case, validate_case  # noqa: E402
from .base.errors import (AccuracyWarning, CaseError, FlexmechError, FlexmechWarning, Interrupted, MechanismError,  # noqa: E402
                          MechanismWarning, SolverError, StabilityWarning, ValidityWarning)
from .base.families import FAMILIES, MODELS, SUPERPOSITION_MODELS, Family, family  # noqa: E402
from .mechanism import Mechanism  # noqa: E402
from .run.simulate import simulate  # noqa: E402
from .run.stepping import Simulation  # noqa: E402

__all__ = ["load_case", "validate_case", "apply_overrides", "simulate", "Simulation", "Case", "Mechanism", "MODELS",
           "SUPERPOSITION_MODELS", "FAMILIES", "Family", "family", "FlexmechError", "CaseError", "MechanismError", "SolverError", "Interrupted", "case_path",
           "case_names", "FlexmechWarning", "ValidityWarning", "AccuracyWarning", "MechanismWarning", "StabilityWarning",
           "__version__"]
