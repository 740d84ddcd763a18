"""Fatigue life of the flexible links: rainflow counting, mean-stress correction, Miner's rule.

The stress history of every outer fibre at every mesh station (:class:`flexmech_py.strength.stress.StressEnvelope`)
over one repeating history -- the periodic steady state's period, or a run window of whole crank
cycles -- is counted by rainflow (ASTM E1049-85 section 5.4.4, the ``rainflow`` package) after it is
rotated to start and end at its largest peak, as a repeating history is counted: every reversal
then closes a cycle.  Each cycle's amplitude S_a = range / 2 at mean S_m is corrected to the
zero-mean amplitude (``goodman``: S_a / (1 - S_m / S_u); ``gerber``: S_a / (1 - (S_m / S_u)^2);
``none``; a compressive mean is not credited), its life N read off the material's S-N line
S_a = a N^b (no damage at or below the endurance limit), and Miner's sum D = sum n_i / N_i gives
the damage of one history; the life is 1 / D histories, in crank cycles and hours at the operating
speed.  docs/theory.md section 22.3 has the method and its limits.

Life goes as stress to the power 1 / b (b about -0.1: the tenth power), so the stress error of the
run (its error budget, else its step-doubling estimate) is carried into a life interval.
"""

from __future__ import annotations

import math

import numpy as np

from ..base.errors import CaseError, FlexmechError
from .stress import FIBRES

try:   # the optional extra 'fatigue' (pip install 'flexmech[fatigue]')
    import rainflow
except ImportError:   # pragma: no cover - exercised only without the extra
    rainflow = None

__all__ = ["CORRECTIONS", "rainflow_cycles", "equivalent_amplitude", "cycle_damage", "link_fatigue",
           "fatigue_summary", "life_interval", "require_rainflow", "LIFE_ERROR_WARN", "TOP_CYCLES"]

CORRECTIONS = ("goodman", "gerber", "none")
#: a life whose stress error makes it uncertain by more than this fraction is reported with a warning
LIFE_ERROR_WARN = 0.3
#: the cycles of the critical station listed with their share of its damage
TOP_CYCLES = 5


def require_rainflow() -> None:
    """FlexmechError naming the extra when the rainflow package is missing."""
    if rainflow is None:
        raise FlexmechError("fatigue life needs the optional package 'rainflow': pip install 'flexmech[fatigue]'")


def _turning_points(y: np.ndarray) -> np.ndarray:
    """Indices of y's reversals with its first and last points (flat runs collapsed to their first point):
    the same cycles as the whole series, at a fraction of the cost of counting every sample."""
    d = np.diff(y)
    nz = np.flatnonzero(d != 0.0)
    if nz.size == 0:
        return np.array([0])
    s = np.sign(d[nz])
    turns = nz[1:][s[1:] != s[:-1]]            # the sample where the slope changes sign
    return np.concatenate([[0], turns, [y.size - 1]])


def rainflow_cycles(y: np.ndarray, repeating: bool = True) -> np.ndarray:
    """(k, 4) cycles of history y: range, mean, count (1 or 0.5), index where the cycle starts in y.
    ``repeating``: y is one period of a repeating history (its last sample the one before its first):
    counted from its largest peak round to it again, so that every cycle closes."""
    require_rainflow()
    y = np.asarray(y, float)
    if y.size < 2:
        return np.empty((0, 4))
    order = np.arange(y.size)
    if repeating:
        k = int(np.argmax(np.abs(y - 0.5 * (y.max() + y.min()))))
        order = np.concatenate([order[k:], order[:k + 1]])
    idx = order[_turning_points(y[order])]
    out = [(rng, mean, count, idx[i0]) for rng, mean, count, i0, _ in rainflow.extract_cycles(y[idx])]
    return np.array(out, float).reshape(-1, 4)


def equivalent_amplitude(amp: np.ndarray, mean: np.ndarray, ultimate: float | None, correction: str) -> np.ndarray:
    """Zero-mean amplitude [Pa] of cycles of amplitude ``amp`` at ``mean``; inf where the mean reaches the
    ultimate strength (the part fails in the first cycle)."""
    if correction == "none":
        return np.asarray(amp, float)
    if not ultimate:
        raise CaseError("material.ultimate_strength", f"the {correction} mean-stress correction needs the ultimate "
                                                      "strength; give it in the link's material, or use --fatigue none")
    r = np.clip(np.asarray(mean, float), 0.0, None) / ultimate
    denom = 1.0 - (r if correction == "goodman" else r * r)
    with np.errstate(divide="ignore"):
        return np.where(denom > 0.0, amp / np.where(denom > 0, denom, 1.0), np.inf)


def cycle_damage(cyc: np.ndarray, mat: dict, correction: str) -> np.ndarray:
    """Miner damage n / N(S_eq) of each cycle of ``cyc`` (rainflow_cycles rows) in material ``mat``."""
    if cyc.shape[0] == 0:
        return np.empty(0)
    s_eq = equivalent_amplitude(0.5 * cyc[:, 0], cyc[:, 1], mat.get("ultimate_strength"), correction)
    a, b = mat["basquin_coefficient"], mat["basquin_exponent"]
    with np.errstate(divide="ignore", over="ignore"):
        n_fail = np.where(s_eq > 0, (s_eq / a) ** (1.0 / b), np.inf)
    with np.errstate(divide="ignore"):
        dmg = cyc[:, 2] / n_fail
    dmg[s_eq <= mat.get("endurance_limit", 0.0)] = 0.0
    return dmg


def _check_material(name: str, mat: dict | None) -> None:
    if not mat or "basquin_coefficient" not in mat:
        raise CaseError(f"links.{name}.material", "the fatigue life needs the link's S-N line: give material = "
                                                  "'6061-T6' (or another named one) or basquin_coefficient and "
                                                  "basquin_exponent in its material table")


def _share(d: float, total: float) -> float:
    """A cycle's share of a damage sum (an infinite sum: 1 for each cycle that fails at once)."""
    if math.isinf(total):
        return 1.0 if math.isinf(d) else 0.0
    return float(d / total) if total > 0 else 0.0


def link_fatigue(name: str, length: float, fractions: np.ndarray, sig: np.ndarray, t: np.ndarray, mat: dict | None,
                 correction: str) -> dict:
    """Damage of one history at every station and fibre of a link ((2, n+1, nf) stresses ``sig`` [Pa]
    at times t); the critical station and the cycles that dominate its damage."""
    _check_material(name, mat)
    dmg = np.zeros(sig.shape[:2])
    best = (-1.0, -1.0, 0, 0, None, None)
    for f in range(sig.shape[0]):
        for k in range(sig.shape[1]):
            cyc = rainflow_cycles(sig[f, k, :-1])     # the last frame repeats the first
            d = cycle_damage(cyc, mat, correction)
            dmg[f, k] = float(d.sum())
            key = (dmg[f, k], float(np.max(np.abs(sig[f, k]))))   # infinite damage: the most stressed station
            if key > best[:2]:
                best = (*key, f, k, cyc, d)
    total, _, f, k, cyc, d = best
    top = np.argsort(-d)[:TOP_CYCLES] if d is not None and d.size else []
    cycles = [{"range_Pa": float(cyc[i, 0]), "mean_Pa": float(cyc[i, 1]), "count": float(cyc[i, 2]),
               "t_start_s": float(t[int(cyc[i, 3])]), "damage_share": _share(d[i], total)}
              for i in top]
    return {"damage_per_history": float(total), "critical_station": {"fraction": float(fractions[k]),
            "x_m": float(fractions[k] * length), "fibre": FIBRES[f]}, "dominant_cycles": cycles,
            "station_damage": dmg.max(axis=0).tolist(), "material": mat.get("name"),
            "basquin_exponent": mat["basquin_exponent"]}


def life_interval(life: float, stress_error: float | None, exponent: float) -> tuple[float, float] | None:
    """(low, high) life when the stresses are off by +-stress_error (a fraction): life ~ S^(1/b)."""
    if stress_error is None or not math.isfinite(life) or not math.isfinite(stress_error):
        return None
    e = min(stress_error, 0.99)
    return life * (1.0 + e) ** (1.0 / exponent), life * (1.0 - e) ** (1.0 / exponent)


def fatigue_summary(per_link: dict, history_s: float, period_s: float | None, errors: dict) -> tuple[dict, list]:
    """(summary, warnings): per link the life in histories, crank cycles and hours with its interval
    from the stress error ``errors[link]``; the critical link."""
    out, warnings = {}, []
    for name, r in per_link.items():
        d = r["damage_per_history"]
        life_h = math.inf if d <= 0 else 1.0 / d
        cycles = life_h * history_s / period_s if period_s else None
        r = dict(r, life_histories=life_h, life_cycles=cycles, life_hours=life_h * history_s / 3600.0,
                 stress_error=errors.get(name))
        b = r.pop("basquin_exponent", None)
        span = life_interval(life_h, r["stress_error"], b) if b else None
        if span is not None:
            r["life_hours_interval"] = [x * history_s / 3600.0 for x in span]
            spread = max(abs(span[0] / life_h - 1.0), abs(span[1] / life_h - 1.0)) if life_h not in (0, math.inf) else 0
            if spread > LIFE_ERROR_WARN:
                warnings.append(f"{name}: the fatigue life is uncertain by {spread:.0%} (its stresses by "
                                f"{r['stress_error']:.1%}; life goes as stress to the power {1.0 / b:.1f}); a "
                                "smaller step or a finer mesh narrows it (the run's error budget names which)")
        out[name] = r
    crit = min(out, key=lambda n: out[n]["life_hours"], default=None)
    return {"links": out, "critical_link": crit, "history_s": history_s, "period_s": period_s}, warnings
