"""What the page of a ``flexmech stability`` result shows (``stability.csv``,
``stability_regions.csv``): as ``stability.png``, the growth rate ln max|mu| / T against the crank
speed with the threshold and the unstable regions shaded and labelled by their multiplier's type,
and the frozen natural-frequency bands with the lines k Omega / 2."""

from __future__ import annotations

import csv
import re
from pathlib import Path

import numpy as np

from ..base.errors import FlexmechError
from ..studies.floquet import STABLE_RATE
from ..figures.study_plots import part_spans, region_label
from .pack import finite

__all__ = ["read_csv_table", "stability_payload", "HARMONIC_LINES", "BANDS"]

#: lines k Omega / 2 drawn, k = 1..HARMONIC_LINES, and frequency bands drawn at most (as stability.png)
HARMONIC_LINES = 8
BANDS = 3


def read_csv_table(path: Path) -> tuple[dict, dict]:
    """({column: array of floats, or list of str for a text column}, {column: unit}) of a CSV file
    flexmech writes (``#`` comment lines, one of them ``# units: ...``, then a header)."""
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except OSError as exc:
        raise FlexmechError(f"{path}: cannot be read ({exc.strerror or exc})") from None
    units = next((ln.split(":", 1)[1].strip().split(",") for ln in lines if ln.startswith("# units:")), [])
    rows = list(csv.reader(ln for ln in lines if ln and not ln.startswith("#")))
    if not rows:
        raise FlexmechError(f"{path}: no header line; not a table written by flexmech")
    head, body = rows[0], rows[1:]
    out = {}
    for k, name in enumerate(head):
        cells = [r[k] if k < len(r) else "" for r in body]
        try:
            out[name] = np.array([float(c) if c else np.nan for c in cells])
        except ValueError:
            out[name] = cells
    return out, dict(zip(head, units))


def stability_payload(folder: Path) -> dict:
    """The page data of the stability chart in ``folder``."""
    path = folder / "stability.csv"
    cols, _ = read_csv_table(path)
    if "speed" not in cols or "growth_rate" not in cols:
        raise FlexmechError(f"{path}: has no speed and growth_rate columns; not written by flexmech stability")
    ok = np.isfinite(cols["growth_rate"]) & np.isfinite(cols["speed"])
    order = np.argsort(cols["speed"][ok])
    pick = np.flatnonzero(ok)[order]
    sp = cols["speed"][pick]
    text = {c: [cols[c][i] for i in pick] for c in ("multiplier",) if isinstance(cols.get(c), list)}
    stable = cols.get("stable", np.ones(len(ok)))[pick] > 0.5
    points = [{"x": float(sp[i]), "y": float(cols["growth_rate"][pick[i]]),
               "mu": finite(cols.get("max_abs_mu", np.full(len(ok), np.nan))[pick[i]]),
               "type": "stable" if stable[i] else (text.get("multiplier", [""] * sp.size)[i] or "unstable")}
              for i in range(sp.size)]
    bands = []
    for k in range(1, BANDS + 1):
        lo, hi = cols.get(f"omega{k}_min"), cols.get(f"omega{k}_max")
        if isinstance(lo, np.ndarray) and isinstance(hi, np.ndarray):
            bands.append({"name": f"ω{k} along the cycle", "lo": lo[pick].tolist(), "hi": hi[pick].tolist()})
    failed = [{"x": finite(s), "error": str(e)} for s, e in zip(cols["speed"], cols.get("error", []) or [])
              if e] if isinstance(cols.get("error"), list) else []
    title, settings = _title(path)
    return {"kind": "stability", "title": title, "settings": settings, "speed": sp.tolist(), "points": points,
            "threshold": STABLE_RATE, "bands": bands, "harmonics": list(range(1, HARMONIC_LINES + 1)),
            "regions": _regions(folder / "stability_regions.csv"), "failed": failed}


def _title(path: Path) -> tuple[str, str]:
    """(the case's title, the chart's settings) from the file's first comment line
    (``# case 'TITLE'; model ...``)."""
    with open(path, encoding="utf-8") as f:
        first = f.readline().strip().lstrip("#").strip()
    m = re.match(r"case (['\"])(.*?)\1; (.*)", first)
    return (m.group(2), m.group(3)) if m else ("flexmech stability", first)


def _regions(path: Path) -> list[dict]:
    """The parts of the unstable regions: the span shaded (halfway to the samples on either side, as
    stability.png), the multiplier type and its label, the largest |mu| and where."""
    if not path.is_file():
        return []
    cols, _ = read_csv_table(path)
    regions: dict = {}
    for i in range(len(cols.get("region", []))):
        amin, amax = finite(cols["angle_min_deg"][i]), finite(cols["angle_max_deg"][i])
        part = {"from": finite(cols["speed_from"][i]), "to": finite(cols["speed_to"][i]),
                "type": cols["multiplier"][i] if isinstance(cols.get("multiplier"), list) else "",
                "angle_deg": None if amin is None else (amin, amax), "max_abs_mu": finite(cols["max_abs_mu"][i]),
                "at": finite(cols["at_speed"][i]), "growth_rate": finite(cols["growth_rate"][i])}
        reg = regions.setdefault(int(cols["region"][i]), {"below": finite(cols["stable_below"][i]),
                                                          "above": finite(cols["stable_above"][i]), "parts": []})
        reg["parts"].append(part)
    out = []
    for lo, hi, part in part_spans(list(regions.values())):
        out.append({"lo": lo, "hi": hi, "type": part["type"], "label": region_label(part), "from": part["from"],
                    "to": part["to"], "max_abs_mu": part["max_abs_mu"], "at": part["at"],
                    "growth_rate": part["growth_rate"]})
    return out
