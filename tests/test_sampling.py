"""Monte-Carlo sampling (flexmech_py/studies/sampling.py, ``flexmech sweep --sample``): the distributions'
inverse CDFs, Latin-hypercube and Sobol' stratification, reproducibility from the seed, the
statistics and correlations, and the command's files and exit codes."""

from __future__ import annotations

import csv
import math

import numpy as np
import pytest
from scipy import stats

from flexmech_py.cli import main
from flexmech_py.base.errors import CaseError
from flexmech_py.studies.sampling import correlations, draw, parse_sample, statistics, unit_points
from flexmech_py.studies.sweep import VARYING_COLUMNS

from conftest import CASES

SEED = CASES / "fourbar_constant_speed.toml"
DISTS = ["a=normal:2.0:0.1", "b=uniform:-1:3", "c=lognormal:0.04:0.01"]


def _rows(path):
    with open(path) as f:
        return list(csv.DictReader(line for line in f if not line.startswith("#")))


def _probabilities(d, x):
    """The CDF of each distribution at the drawn values: back to the unit interval."""
    x = np.asarray(x)
    if d.kind == "uniform":
        return (x - d.a) / (d.b - d.a)
    if d.kind == "normal":
        return stats.norm.cdf(x, d.a, d.b)
    s2 = math.log1p((d.b / d.a) ** 2)
    return stats.norm.cdf((np.log(x) - math.log(d.a) + 0.5 * s2) / math.sqrt(s2))


def test_parse_sample_forms_and_errors():
    d = parse_sample("links.coupler.area = normal:4.06e-5:1e-6")
    assert (d.key, d.kind, d.a, d.b) == ("links.coupler.area", "normal", 4.06e-5, 1e-6)
    for bad, needle in [("x", "KEY.PATH=DIST"), ("x=gauss:1:2", "one of"), ("x=normal:1", "two finite"),
                        ("x=normal:1:0", "SD must be > 0"), ("x=uniform:2:1", "LO must be below HI"),
                        ("x=lognormal:-1:0.1", "MEAN must be > 0"), ("x=normal:1:nan", "two finite")]:
        with pytest.raises(CaseError, match=needle):
            parse_sample(bad)
    with pytest.raises(CaseError, match="twice"):
        draw([parse_sample("a=normal:1:1"), parse_sample("a=uniform:0:1")], 4, 0)
    with pytest.raises(CaseError, match="--method"):
        unit_points(2, 4, 0, "halton")


@pytest.mark.parametrize("method", ["lhs", "sobol"])
def test_every_input_has_one_sample_per_equal_probability_stratum(method):
    # Latin hypercube: by construction; scrambled Sobol' with N = 2^m: each 1-D projection is a (0, m, 1)-net.
    # Mapping the drawn values back through each CDF checks the inverse CDFs too.
    n = 64
    dists = [parse_sample(s) for s in DISTS]
    points, notes = draw(dists, n, seed=3, method=method)
    assert not notes and len(points) == n
    for d in dists:
        u = _probabilities(d, [p[d.key] for p in points])
        assert np.array_equal(np.sort(np.floor(u * n + 1e-9).astype(int)), np.arange(n)), d.key


def test_random_is_not_stratified_and_sobol_warns_off_powers_of_two():
    u, _ = unit_points(1, 64, 3, "random")
    assert len(set(np.floor(u[:, 0] * 64).astype(int))) < 64    # ~40 of 64 strata hit (1 - 1/e)
    _, notes = unit_points(2, 100, 3, "sobol")
    assert notes and "power of 2" in notes[0] and "128 or 64" in notes[0]


def test_sample_moments_and_reproducibility_from_the_seed():
    dists = [parse_sample(s) for s in DISTS]
    pts, _ = draw(dists, 4096, seed=11)
    for d, mean, sd in zip(dists, (2.0, 1.0, 0.04), (0.1, 4 / math.sqrt(12), 0.01)):
        x = np.array([p[d.key] for p in pts])
        assert np.mean(x) == pytest.approx(mean, abs=0.002 * sd) and np.std(x) == pytest.approx(sd, rel=0.01), d.key
    for method in ("lhs", "sobol", "random"):
        assert draw(dists, 16, 5, method) == draw(dists, 16, 5, method)
        assert draw(dists, 16, 5, method)[0] != draw(dists, 16, 6, method)[0]


def test_statistics_and_correlations():
    rng = np.random.default_rng(0)
    x, z = rng.normal(size=200), rng.normal(size=200)
    y = np.exp(x) + 0.01 * z                       # monotonic in x, nearly independent of z
    s = statistics({"y": y})[0]
    assert s["n"] == 200 and s["mean"] == pytest.approx(np.mean(y)) and s["sd"] == pytest.approx(np.std(y, ddof=1))
    assert (s["p5"], s["p50"], s["p95"]) == tuple(np.percentile(y, [5, 50, 95]))
    c = correlations({"x": x, "z": z, "k": np.ones(200)}, {"y": y})
    assert [r["input"] for r in c] == ["x", "z", "k"] and [r.get("rank") for r in c] == [1, 2, None]
    assert c[0]["spearman"] > 0.999 and c[0]["pearson"] < c[0]["spearman"]   # rank: monotonic, not linear
    assert abs(c[1]["spearman"]) < 0.2 and math.isnan(c[2]["spearman"])


def test_sample_command_files_reproducible_from_the_seed(tmp_path, capsys):
    # the follower's peak strain rises with the mass at the coupler-follower joint (larger inertia load)
    argv = ["sweep", str(SEED), "--sample", "point_masses.1.mass=uniform:0.03:0.045", "--sample",
            "links.coupler.density=normal:2710:20", "--samples", "8", "--set", "solver.t_end=0.03", "--jobs", "1"]
    assert main(argv + ["--seed", "4", "--out", str(tmp_path / "a")]) == 0
    out = capsys.readouterr().out
    assert "8 runs (8 computed, 0 cached, 0 failed, 0 retried)" in out and "strain_follower_mid_maxabs: mean" in out
    assert main(argv + ["--seed", "4", "--out", str(tmp_path / "b"), "--no-plots"]) == 0
    assert main(argv + ["--seed", "5", "--out", str(tmp_path / "c"), "--no-plots"]) == 0
    a, b, c = (_rows(tmp_path / x / "samples.csv") for x in "abc")
    strip = [{k: v for k, v in r.items() if k not in VARYING_COLUMNS} for r in a]
    assert strip == [{k: v for k, v in r.items() if k not in VARYING_COLUMNS} for r in b]
    assert [r["point_masses.1.mass"] for r in a] != [r["point_masses.1.mass"] for r in c]
    assert [int(r["sample"]) for r in a] == list(range(8)) and all(r["status"] == "ok" for r in a)
    st = {r["column"]: r for r in _rows(tmp_path / "a" / "statistics.csv")}
    y = np.array([float(r["strain_follower_mid_maxabs"]) for r in a])
    assert float(st["strain_follower_mid_maxabs"]["mean"]) == pytest.approx(np.mean(y), rel=1e-9)
    cor = [r for r in _rows(tmp_path / "a" / "correlations.csv") if r["output"] == "strain_follower_mid_maxabs"]
    assert cor[0]["input"] == "point_masses.1.mass" and float(cor[0]["spearman"]) > 0.8 and cor[0]["rank"] == "1"
    assert (tmp_path / "a" / "samples.png").stat().st_size > 10_000 and not (tmp_path / "b" / "samples.png").exists()


def test_sample_failures_exit_3_and_bad_first_sample_exit_2(tmp_path, capsys):
    base = ["sweep", str(SEED), "--set", "solver.t_end=0.002", "--jobs", "1", "--samples", "8"]
    # an area spread reaching below zero: the negative samples fail, the others are kept
    rc = main(base + ["--sample", "links.coupler.area=uniform:-4e-5:4e-5", "--seed", "1", "--out", str(tmp_path / "f")])
    io = capsys.readouterr()
    rows = _rows(tmp_path / "f" / "samples.csv")
    nbad = sum(float(r["links.coupler.area"]) <= 0 for r in rows)
    assert 0 < nbad < 8 and rc == 3 and sum(r["status"] == "error" for r in rows) == nbad
    assert f"flexmech: error: {nbad} of 8 runs failed" in io.err and "must be > 0" in io.err
    # a mistyped key: one line, exit 2, nothing written
    rc = main(base + ["--sample", "links.coupler.aera=normal:4e-5:1e-6", "--out", str(tmp_path / "n")])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1 and "the first sample (links.coupler.aera=" in err
    assert not (tmp_path / "n").exists()
    assert main(base + ["--sample", "links.coupler.area=normal:4e-5", "--out", str(tmp_path / "n")]) == 2
    assert main(["sweep", str(SEED), "--sample", "links.coupler.area=normal:4e-5:1e-6"]) == 2   # no --samples
