"""`flexmech reproduce` at reduced size: its report reads as a document (each claim, the measured
number, the physical reading, the validity limits) and its figures say what they show, with units.
The sentences that used to contradict the numbers are checked where they are made."""

import re

import numpy as np
import pytest

from flexmech_py.studies import reproduce as rp
from flexmech_py.studies import seed_report
from flexmech_py.cli import main
from flexmech_py.studies.gap import gap_table
from flexmech_py.figures.plots import have_matplotlib

T_END = 0.02   # s: no validity limit is passed this early


@pytest.fixture(scope="module")
def reduced(tmp_path_factory):
    """reproduce(t_end=0.02, gap=False) with every figure's title and axis labels recorded."""
    out = tmp_path_factory.mktemp("reproduce")
    drawn = {}
    real = rp.line_figure
    mp = pytest.MonkeyPatch()
    mp.setattr(rp, "line_figure", lambda path, panels, **kw: drawn.setdefault(path.name, (panels, kw))
               and real(path, panels, **kw))
    try:
        report = rp.reproduce(out, t_end=T_END, gap=False)
    finally:
        mp.undo()
    return out, report.read_text(encoding="utf-8"), drawn


def test_report_has_the_reader_sections(reduced):
    out, text, _ = reduced
    for heading in ("## Summary", "## Runs", "### Where the four-bar's models are valid",
                    "### Claim 1: midspan strains of case I and case II", "### Claim 2: the rigid-inertia forces",
                    "## Two-link manipulator (seed Figs. 9-12)", "## One-pass coupled model",
                    "**Reading, from the coupled run's energy columns.**", "**Why so small, when the loads differ by"):
        assert heading in text, heading
    for fig in re.findall(r"!\[[^]]*\]\(([^)]+)\)", text):      # every linked figure was written
        assert (out / fig).is_file(), fig
    if have_matplotlib():   # the seed's Figs. 2 and 9 (the mechanisms) are drawn, not missing
        assert "fig2_fourbar.png" in text and "fig9_manipulator.png" in text


def test_report_has_frequencies_along_the_motion_and_drawings(reduced):
    """The four-bar's and the manipulator's frozen frequencies along the motion (their bands in the
    report are those of the CSV) and one drawing per seed case."""
    import csv

    import numpy as np

    out, text, _ = reduced
    assert "## Natural frequencies along the motion, and the mechanisms drawn" in text
    for name in ("fourbar_constant_speed", "manipulator_bricout"):
        with open(out / "modes" / name / "frequencies_along.csv", encoding="utf-8") as fh:
            rows = list(csv.DictReader(line for line in fh if not line.startswith("#")))
        f1 = np.array([float(r["f1_hz"]) for r in rows])
        assert f1.size in (72, 48) and np.all(f1 > 0)
        assert f"| 1 | {f1.min():.4g} | {f1.max():.4g} |" in text
    assert "k = 4" in text                     # the four-bar's third mode meets 4 Omega (docs/cli.md)
    assert "No speed harmonics: base turns less than a revolution over the run." in text   # the manipulator
    if have_matplotlib():
        for name in rp.SEED_CASES:
            assert f"({name}_drawing.png)" in text and (out / f"{name}_drawing.png").is_file()
        assert (out / "fourbar_constant_speed_frequencies_along.png").is_file()


def test_report_states_no_infinite_times_and_no_false_limits(reduced):
    _, text, _ = reduced
    assert "inf s" not in text and "t = inf" not in text and "| inf |" not in text
    assert "never within the run (0.02 s)" in text
    # this short run passes no limit, and the report says so rather than the full run's story
    assert "The four-bar stays within the small-deformation range over this run (0.02 s)" in text
    assert "leaves the small-deformation range" not in text
    assert "No limit is passed within the run (0.02 s)" in text
    assert "the 3 % bound holds" in text


def test_report_numbers_are_the_runs(reduced):
    out, text, _ = reduced
    from flexmech_py.run.results import read_timeseries

    c, _ = read_timeseries(out / "runs" / "fourbar_hac-coupled" / "timeseries.csv")
    assert f"W = {c['work_inputs'][-1]:.4g} J" in text and f"V = {c['energy_potential'][-1]:.4g} J" in text
    h, _ = read_timeseries(out / "runs" / "fourbar_hac-hac" / "timeseries.csv")
    k, _ = read_timeseries(out / "runs" / "fourbar_hac-classic" / "timeseries.csv")
    d = np.max(np.abs(h["strain_coupler_mid"] - k["strain_coupler_mid"])) / np.max(np.abs(k["strain_coupler_mid"]))
    assert f"| max abs difference / peak, strain_coupler_mid | {100 * d:.3g} %" in text


def test_figures_have_units_distinct_titles_and_say_what_coincides(reduced):
    _, _, drawn = reduced
    titles = [kw["title"] for _, kw in drawn.values()]
    assert len(titles) == len(set(titles))                           # Figs. 10 and 11 no longer share one
    assert "in X (horizontal)" in drawn["fig10_manipulator_bricout_tip_dx_deflection.png"][1]["title"]
    assert "in Y (vertical)" in drawn["fig11_manipulator_bricout_tip_dy_deflection.png"][1]["title"]
    for name, (panels, kw) in drawn.items():
        assert re.search(r"\[[^]]+\]$", kw["xlabel"]), name
        for p in panels:
            assert re.search(r"\[[^]]+\]$", p["ylabel"]), (name, p["ylabel"])
            assert "[1]" not in p["ylabel"] and "_elastic [m]" not in p["ylabel"]
            if "strain" in p["ylabel"]:
                assert p["ylabel"].endswith("[-]")
            if "tip" in p["ylabel"]:
                assert p["ylabel"].endswith("[mm]")
    assert "coincide" in drawn["fig3_coupler_strain.png"][1]["title"]
    fig5 = drawn["fig5_coupler_strain_difference.png"][0]
    assert len(fig5) == 2 and all(len(p["series"]) == 1 for p in fig5)   # case I - case II on its own axis


def test_coupled_drawn_over_nonlinear(reduced):
    _, _, drawn = reduced
    labels = [lab for lab, _, _ in drawn["fig11_manipulator_bricout_tip_dy_deflection.png"][0][0]["series"]]
    assert labels.index(rp.LABEL["coupled"]) > labels.index(rp.LABEL["nonlinear"])


def _study(t_defl):
    row = {"model": "classic", "geometric": "none", "joint": "seed", "elements": 8, "errors": [2.31, 0.9],
           "validity_s": (float("inf"), 0.0018), "kernel_s": 0.1, "failed": ""}
    return {"column": "strain_coupler_mid", "windows": [0.025, 0.05], "rows": [row],
            "reference_validity_s": (t_defl, float("inf")), "reference_kernel_s": 5.0, "ref_elements": 16}


def test_gap_closing_sentence_matches_the_validity_time():
    early = "\n".join(gap_table("fourbar_constant_speed", _study(0.003)))
    assert "Closest over [0, 0.025] s (no window lies inside the small-deflection range: the nonlinear " \
           "deflections pass 2 % of the link lengths at t = 0.003 s, before the shortest window ends" in early
    assert "deflections below 2 %" not in early
    later = "\n".join(gap_table("fourbar_hac", _study(0.0552)))
    assert "Closest over [0, 0.05] s (the longest window before the nonlinear deflections pass 2 % of the " \
           "link lengths at t = 0.0552 s)" in later
    never = "\n".join(gap_table("manipulator_bricout", _study(float("inf"))))
    assert "no deflection exceeds 2 % of its link's length within [0, 0.05] s" in never
    assert "no compressive force exceeds the Euler load within [0, 0.05] s" in never
    assert "inf" not in never and "| never |" in never


def test_validity_bullet_both_ways():
    o = {"max_deflection_over_length": 0.51, "max_deflection_link": "coupler", "max_strain": 0.0168,
         "max_compression_over_euler": 9.14}
    past = seed_report._validity_bullet({"overall": o, "eps_y": 0.004, "valid_until": 0.0549, "t_end": 0.25,
                                         "err": None})
    assert past.startswith("- **The four-bar as specified leaves the small-deformation range at t = 0.0549 s.**")
    assert "4.2 times the 0.40 % yield strain of 6061-T6" in past and "would yield and buckle" in past
    assert "a strain of 1.68 %" in past
    inside = seed_report._validity_bullet({"overall": o, "eps_y": 0.004, "valid_until": None, "t_end": 0.02,
                                           "err": None})
    assert "stays within" in inside and "yield and buckle" not in inside
    # the digits follow the run's error budget: 30 % time-step + mesh error leaves two digits
    rough = seed_report._validity_bullet({"overall": o, "eps_y": 0.004, "valid_until": 0.0549, "t_end": 0.25,
                                          "err": 0.3})
    assert "a strain of 1.7 %" in rough and "deflection of 50 %" in rough and "up to 30 % of the peak strains" in rough


def test_when_and_torque_work():
    assert seed_report.when(None, 0.25) == "never within the run (0.25 s)"
    assert seed_report.when(0.05486, 0.25) == "at t = 0.05486 s"
    th = np.linspace(0.0, 24.0, 200_001)
    m = 1.0 + 0.5 * np.sin(th)
    w = seed_report.torque_work({"law": "force", "constant": 1.0, "sin": [0.5]}, 0.0, th)
    assert w[-1] == pytest.approx(np.sum(0.5 * (m[1:] + m[:-1]) * np.diff(th)), rel=1e-9)
    assert seed_report.torque_work({"law": "force", "constant": 1.0, "time_harmonics": [[1, 2, 0]]}, 0, th) is None


def test_cli_reproduce_reduced(tmp_path, capsys):
    assert main(["reproduce", "--out", str(tmp_path), "--t-end", "0.005", "--no-gap"]) == 0
    assert (tmp_path / "report.md").is_file() and "wrote" in capsys.readouterr().out
