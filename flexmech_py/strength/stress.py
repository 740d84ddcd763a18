"""Normal stress at the outer fibres of every flexible link, at every mesh station, and its envelope.

The stress is the model's own: its curvature at the mesh nodes (:meth:`Result.node_curvatures`, the
mean of the two elements at an interior node, as the ``strain`` and ``curvature`` outputs) and its
element axial forces (``Result.axial``, the mean of the two elements at an interior node, as the
``axial_force`` output), in every model family (docs/theory.md section 22.2):

    sigma_bottom = N / A + E c kappa      (the fibre at eta = -c: the ``strain`` output's fibre)
    sigma_top    = N / A - E c kappa

so ``(sigma_bottom - N / A) / E`` is the ``strain`` output and ``N`` the ``axial_force`` output at a
named station.  Shear stress is left out (slender links: it vanishes at the outer fibres where the
normal stress peaks); the safety factor against yield is ``yield_strength / max |sigma|``.

:class:`StressEnvelope` takes a run block after block (an observer of
:func:`flexmech_py.run.runner.execute`, or one whole Result): per station the largest tension and
compression, when and on which fibre; per link the critical station and the safety factor; and,
inside a time ``window``, the stress history of every station for the fatigue count
(:mod:`flexmech_py.strength.fatigue`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..mechanism.materials import material_values

__all__ = ["LinkStations", "StressEnvelope", "station_values", "link_stations", "in_window", "FIBRES"]

#: the outer fibres: "bottom" at eta = -c (the ``strain`` output's fibre), "top" at eta = +c
FIBRES = ("bottom", "top")


@dataclass
class LinkStations:
    """The mesh stations of flexible link ``index`` (``fractions`` of its length) and what turns its
    curvature and axial force into stress: area [m^2], Young's modulus [Pa], outer-fibre distance c
    [m], yield strength [Pa] (None when the case gives neither a material nor a yield strain)."""

    name: str
    index: int
    length: float
    fractions: np.ndarray
    area: float
    youngs_modulus: float
    half_depth: float
    yield_strength: float | None
    material: dict | None


def in_window(t: np.ndarray, t_last: float, window) -> np.ndarray:
    """Mask of a block's frames after ``t_last`` (the frames seen before) and inside ``window`` (t0, t1)."""
    keep = t > t_last
    if window is not None:
        keep &= (t >= window[0] - 1e-12) & (t <= window[1] + 1e-12)
    return keep


def link_stations(case, fe) -> list[LinkStations]:
    """The stations of every flexible link of a run's case (``fe``: its mesh, with ``node_frac``)."""
    out = []
    for li, ln in enumerate(case["links"]):
        if ln.get("rigid"):
            continue
        mat = material_values(ln["material"], f"links.{ln['name']}.material") if ln.get("material") else None
        sy = mat.get("yield_strength") if mat else None
        if sy is None and ln.get("yield_strain"):
            sy = ln["yield_strain"] * ln["youngs_modulus"]
        out.append(LinkStations(ln["name"], li, ln["length"], np.asarray(fe.node_frac[li], float), ln["area"],
                                ln["youngs_modulus"], ln["half_depth"], sy, mat))
    return out


def station_values(block, st: LinkStations) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(N, kappa, sigma) of link ``st`` over a block's frames: the axial force [N] and curvature [1/m]
    at its n+1 stations (n+1, nf) and the outer-fibre stresses [Pa] (2, n+1, nf): bottom, top."""
    kap = block.node_curvatures(st.index)
    ax = block.axial[block.fe.link_elements(st.index)]
    n = ax.shape[0]
    nst = np.empty((n + 1, ax.shape[1]))
    nst[0], nst[n] = ax[0], ax[n - 1]
    nst[1:n] = 0.5 * (ax[:n - 1] + ax[1:])
    s_ax, s_b = nst / st.area, st.youngs_modulus * st.half_depth * kap
    return nst, kap, np.stack([s_ax + s_b, s_ax - s_b])


@dataclass
class _LinkEnvelope:
    st: LinkStations
    smax: np.ndarray
    smin: np.ndarray
    tmax: np.ndarray
    tmin: np.ndarray
    fmax: np.ndarray          # fibre index of the largest tension at each station
    fmin: np.ndarray
    history: list = field(default_factory=list)   # (2, n+1, nf) blocks inside the window

    @classmethod
    def empty(cls, st: LinkStations) -> "_LinkEnvelope":
        m = st.fractions.size
        return cls(st, np.full(m, -np.inf), np.full(m, np.inf), np.zeros(m), np.zeros(m), np.zeros(m, int),
                   np.zeros(m, int))

    def add(self, t: np.ndarray, sig: np.ndarray) -> None:
        flat_max = sig.max(axis=0)                    # (n+1, nf): the larger of the two fibres
        flat_min = sig.min(axis=0)
        kmax, kmin = flat_max.argmax(axis=1), flat_min.argmin(axis=1)
        rows = np.arange(flat_max.shape[0])
        vmax, vmin = flat_max[rows, kmax], flat_min[rows, kmin]
        up, down = vmax > self.smax, vmin < self.smin
        self.smax[up], self.tmax[up] = vmax[up], t[kmax[up]]
        self.fmax[up] = sig[:, rows, kmax].argmax(axis=0)[up]
        self.smin[down], self.tmin[down] = vmin[down], t[kmin[down]]
        self.fmin[down] = sig[:, rows, kmin].argmin(axis=0)[down]


class StressEnvelope:
    """Stress envelopes of every flexible link over a run's frames inside ``window`` = (t0, t1) [s]
    (None: every frame), fed block by block (:meth:`add`), and with ``keep_history`` the stress
    history of every station there (for the fatigue count).  The stations are the nodes of ``fe`` (a
    mesh), or of the first block's mesh when ``fe`` is None.  Frames that two blocks share (a block
    starts with the previous block's last frame) count once."""

    def __init__(self, case, fe=None, window: tuple[float, float] | None = None, keep_history: bool = False):
        self.case = case
        self.window = window
        self.keep_history = keep_history
        self.meshed = fe is not None
        self.links = [_LinkEnvelope.empty(st) for st in link_stations(case, fe)] if fe is not None else []
        self.t_hist: list = []
        self.t_last = -np.inf
        self.config = None          # the rigid configuration at the first frame: (ox, oy, phi) per link

    def add(self, block) -> None:
        if not self.meshed:     # no mesh given: the run's own (model = auto picks the family as it starts)
            self.links = [_LinkEnvelope.empty(st) for st in link_stations(self.case, block.fe)]
            self.meshed = True
        keep = in_window(block.t, self.t_last, self.window)
        if not np.any(keep) or block.axial is None:
            return
        t = block.t[keep]
        if self.config is None and block.motion is not None:
            k = int(np.argmax(keep))
            self.config = (block.motion.ox[k].copy(), block.motion.oy[k].copy(), block.motion.phi[k].copy())
        for env in self.links:
            _, _, sig = station_values(block, env.st)
            sig = sig[:, :, keep]
            env.add(t, sig)
            if self.keep_history:
                env.history.append(sig)
        if self.keep_history:
            self.t_hist.append(t)
        self.t_last = float(t[-1])

    def histories(self):
        """(t (nf,), {link: (2, n+1, nf) stresses [Pa] in the window}): what the fatigue count reads."""
        t = np.concatenate(self.t_hist) if self.t_hist else np.empty(0)
        return t, {env.st.name: (np.concatenate(env.history, axis=2) if env.history else
                                 np.empty((2, env.st.fractions.size, 0))) for env in self.links}

    def summary(self) -> dict:
        """Per link: the largest tension and compression (value [Pa], where, when, fibre), the critical
        station (largest |sigma|), the yield strength and the safety factor against it."""
        return {env.st.name: _link_summary(env) for env in self.links}

    def station_rows(self) -> list[dict]:
        """One row per station of every link: its envelope (stress.csv)."""
        rows = []
        for env in self.links:
            st = env.st
            for k, f in enumerate(st.fractions):
                rows.append({"link": st.name, "station": k, "fraction": float(f), "x_m": float(f * st.length),
                             "max_stress_Pa": float(env.smax[k]), "t_max_s": float(env.tmax[k]),
                             "max_fibre": FIBRES[env.fmax[k]], "min_stress_Pa": float(env.smin[k]),
                             "t_min_s": float(env.tmin[k]), "min_fibre": FIBRES[env.fmin[k]],
                             "max_abs_stress_Pa": float(max(env.smax[k], -env.smin[k]))})
        return rows


def _link_summary(env: _LinkEnvelope) -> dict:
    st = env.st
    kt, kc = int(np.argmax(env.smax)), int(np.argmin(env.smin))
    tension = {"stress_Pa": float(env.smax[kt]), "fraction": float(st.fractions[kt]), "t_s": float(env.tmax[kt]),
               "fibre": FIBRES[env.fmax[kt]]}
    compression = {"stress_Pa": float(env.smin[kc]), "fraction": float(st.fractions[kc]),
                   "t_s": float(env.tmin[kc]), "fibre": FIBRES[env.fmin[kc]]}
    crit = tension if tension["stress_Pa"] >= -compression["stress_Pa"] else compression
    peak = abs(crit["stress_Pa"])
    return {"max_tension": tension, "max_compression": compression, "peak_abs_stress_Pa": peak,
            "critical_station": {**crit, "x_m": crit["fraction"] * st.length},
            "yield_strength_Pa": st.yield_strength,
            "safety_factor": (st.yield_strength / peak if st.yield_strength and peak > 0 else
                              (float("inf") if st.yield_strength else None)),
            "material": (st.material or {}).get("name"), "stations": int(st.fractions.size)}
