"""``flexmech fmu``: a case exported as an FMI 2.0 co-simulation unit (flexmech_py.fmu; docs/cli.md)."""

from __future__ import annotations

from .case import load_case
from .base.families import MODELS
from .fmu import export_fmu


def _names(text: str) -> list[str]:
    return [n.strip() for n in text.split(",") if n.strip()]


def add_fmu_parser(sub) -> None:
    """The ``flexmech fmu`` command's options."""
    f = sub.add_parser("fmu", help="export a case as an FMI 2.0 co-simulation unit (needs flexmech[fmi]; "
                                   "joint efforts in, the case's outputs out)")
    f.add_argument("case", help="TOML case file (see docs/cases.md)")
    f.add_argument("--out", required=True, metavar="FILE.fmu", help="the unit to write")
    f.add_argument("--model", choices=MODELS, help="the model the unit runs (default: the case's solver.model)")
    f.add_argument("--inputs", type=_names, default=None, metavar="JOINT,...",
                   help="force-driven joints whose efforts the master sets (default: every force-driven joint)")
    f.add_argument("--outputs", type=_names, default=None, metavar="NAME,...",
                   help="case outputs the unit gives (default: all)")
    f.add_argument("--set", action="append", default=[], metavar="KEY.PATH=VALUE",
                   help="override a case value before export, e.g. --set solver.t_end=2 --set solver.dt=1e-4")


def cmd_fmu(args) -> int:
    case = load_case(args.case, args.set)
    info = export_fmu(case, args.out, args.model, args.inputs, args.outputs)
    print(f"wrote {info.path} (FMI 2.0 co-simulation, model {info.model_name}; inputs {', '.join(info.inputs)}; "
          f"{len(info.outputs)} outputs; communication step a multiple of {info.dt:g} s, up to t = {info.t_end:g} s)")
    return 0
