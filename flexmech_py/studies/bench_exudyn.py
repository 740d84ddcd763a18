"""Side by side with Exudyn (issue 12; docs/performance.md, "Side by side with Exudyn").

The seed four-bar (cases/fourbar_hac.toml) run by flexmech's nonlinear model and by Exudyn
(https://github.com/jgerstmayr/EXUDYN, pip ``exudyn``) with its planar ANCF cable element
(``ObjectANCFCable2D``: cubic in the nodal positions and slopes, geometrically exact), on the same
mesh (``elements_per_link`` elements per link, nodes at the same places), the same step and the same
integrator family (generalized-alpha with the same spectral radius), the same loads (torque
1 + 0.5 sin(alpha) N m on the crank's root node, where alpha is the angle of the crank's tangent
there, and the two point masses at the crank-coupler and coupler-follower joints).  Joints are pins:
coordinate constraints between the end nodes' positions (Exudyn) and shared position DOFs
(flexmech).  Both give the midspan bending strains (curvature x the half depth), compared over the
run, and the CPU time of the time integration (model building not counted on either side).

The seed manipulator (cases/manipulator_bricout.toml) likewise (:func:`manipulator_side_by_side`):
step torques at the base and the elbow through rigid markers on the cables, the elbow mass and hub
inertia as one rigid body welded to link 1's end, the payload a mass point, frames at every step
(its torques ring up to tens of kHz; decimated frames would fold that into the low band), strains
compared after a low-pass.

Exudyn is an optional benchmark dependency: :func:`unavailable` says why the section is skipped.
"""

from __future__ import annotations

import time

import numpy as np
from ..case import load_case
from ..run.simulate import Prepared

__all__ = ["unavailable", "side_by_side", "manipulator_side_by_side", "SEED_TORQUE", "link_geometry", "cable_links",
           "coord_marker", "ground_pin", "tie_nodes", "midspan_sensors", "midspan_strain", "solve_dynamic", "smallest_times",
           "relative_difference"]

SEED_TORQUE = (1.0, 0.5)       # N m: tau = a + b sin(alpha) (cases/fourbar_hac.toml, [drive])


def unavailable() -> str | None:
    """None when Exudyn imports, else the one line that says why the comparison is skipped."""
    try:
        import exudyn  # noqa: F401
    except ImportError:
        return "Exudyn is not installed (pip install exudyn, an optional benchmark dependency): side-by-side skipped"
    return None


def _seed_case(case_path, epl: int, dt: float, t_end: float, rho_inf: float, node_angles: str = "shared"):
    return load_case(case_path, overrides=[f"solver.dt={dt!r}", f"solver.t_end={t_end!r}", "solver.output_every=10",
                                           f"solver.node_angles={node_angles!r}",
                                           "solver.integrator='generalized-alpha'", f"solver.rho_inf={rho_inf!r}",
                                           "solver.error_estimate='none'", f"mesh.elements_per_link={epl}"])


def run_flexmech(case, model: str = "nonlinear", columns=("strain_coupler_mid", "strain_follower_mid", "crank_angle")) -> dict:
    """flexmech's run (nonlinear, or the coupled model of seed Section 3): the output ``columns`` at
    the case's frames, CPU of the kernel [s]."""
    p = Prepared(case)
    p.elastic_checked = True
    r = p.run(model)
    return {"t": r.t, **{k: r.columns[k] for k in columns}, "cpu_s": p.last_cpu["kernel_cpu_s"],
            "newton": r.extra["coupled"]["newton"], "rigid": p.rm}


def link_geometry(case, rm) -> list[tuple]:
    """(start x, y, angle, length, rho A, EA, EI, half depth) of every link at t = 0."""
    km = rm.motion
    out = []
    for li, ln in enumerate(case["links"]):
        out.append((float(km.ox[0, li]), float(km.oy[0, li]), float(km.phi[0, li]), ln["length"],
                    ln["density"] * ln["area"], ln["youngs_modulus"] * ln["area"],
                    ln["youngs_modulus"] * ln["second_moment"], ln["half_depth"]))
    return out


def cable_links(geometry, epl: int, rates=None):
    """A new Exudyn system with every link of ``geometry`` as epl ANCF cable elements on straight
    nodes: (system container, mbs, ground node, nodes per link, elements per link).  ``rates``: per
    link (vx, vy, omega) of its start and its rotation, the nodes' initial velocities of that rigid
    motion (default at rest)."""
    import exudyn as exu
    from exudyn.itemInterface import NodePoint2DSlope1, NodePointGround, ObjectANCFCable2D

    sc = exu.SystemContainer()
    mbs = sc.AddSystem()
    ground = mbs.AddNode(NodePointGround(referenceCoordinates=[0.0, 0.0, 0.0]))
    nodes, elems = [], []
    for li, (x0, y0, ang, length, rho_a, ea, ei, _) in enumerate(geometry):
        c, s = np.cos(ang), np.sin(ang)
        vx, vy, om = (0.0, 0.0, 0.0) if rates is None else rates[li]
        ns = [mbs.AddNode(NodePoint2DSlope1(
            referenceCoordinates=[x0 + k * length / epl * c, y0 + k * length / epl * s, c, s],
            initialVelocities=[vx - om * k * length / epl * s, vy + om * k * length / epl * c, -om * s, om * c]))
              for k in range(epl + 1)]
        elems.append([mbs.AddObject(ObjectANCFCable2D(nodeNumbers=[ns[k], ns[k + 1]], length=length / epl,
                                                      massPerLength=rho_a, bendingStiffness=ei, axialStiffness=ea))
                      for k in range(epl)])
        nodes.append(ns)
    return sc, mbs, ground, nodes, elems


def coord_marker(mbs, node, i):
    """A marker on coordinate i of a node."""
    from exudyn.itemInterface import MarkerNodeCoordinate

    return mbs.AddMarker(MarkerNodeCoordinate(nodeNumber=node, coordinate=i))


def tie_nodes(mbs, na, nb):
    """Equal position displacements of two nodes (of the same reference position): a pin."""
    from exudyn.itemInterface import CoordinateConstraint

    for i in (0, 1):
        mbs.AddObject(CoordinateConstraint(markerNumbers=[coord_marker(mbs, na, i), coord_marker(mbs, nb, i)]))


def ground_pin(mbs, ground, node):
    """The node's position held at its reference (a pin to the ground)."""
    from exudyn.itemInterface import CoordinateConstraint

    for i in (0, 1):
        mbs.AddObject(CoordinateConstraint(markerNumbers=[coord_marker(mbs, ground, 0), coord_marker(mbs, node, i)]))


def _mass_point(mbs, node, mass):
    """A point mass pinned to a node."""
    from exudyn.itemInterface import NodePoint2D, ObjectMassPoint2D

    ref = mbs.GetNodeParameter(node, "referenceCoordinates")
    pm = mbs.AddNode(NodePoint2D(referenceCoordinates=[ref[0], ref[1]]))
    mbs.AddObject(ObjectMassPoint2D(mass=mass, nodeNumber=pm))
    tie_nodes(mbs, node, pm)


def midspan_sensors(mbs, elems, geometry, epl: int, links) -> list:
    """Per link in links, the curvature sensors at its midspan: at a node (even epl) the two elements
    there, whose mean is what flexmech reads at a node; else the middle of the middle element."""
    import exudyn as exu
    from exudyn.itemInterface import SensorBody

    groups = []
    for li in links:
        k = epl // 2
        places = ([(elems[li][k - 1], geometry[li][3] / epl), (elems[li][k], 0.0)] if epl % 2 == 0
                  else [(elems[li][k], 0.5 * geometry[li][3] / epl)])
        groups.append([mbs.AddSensor(SensorBody(bodyNumber=e, localPosition=[x, 0.0, 0.0], storeInternal=True,
                                                outputVariableType=exu.OutputVariableType.CurvatureLocal))
                       for e, x in places])
    return groups


def midspan_strain(mbs, group, half_depth):
    """The strain [-] of one midspan_sensors group: mean curvature x the half depth."""
    return np.mean([mbs.GetSensorStoredData(s)[:, 1] for s in group], axis=0) * half_depth


def solve_dynamic(mbs, nsteps: int, t_end: float, rho_inf: float, write_period: float,
                  absolute_tolerance: float | None = None) -> float:
    """Assemble and integrate (generalized-alpha, Newton tolerance 1e-8 relative and, when given,
    absolute_tolerance on the residual per coordinate, sparse solver, sensors every write_period
    [s]); the calling thread's CPU time of the integration [s] (Exudyn runs single-threaded here:
    parallel.numberOfThreads = 1 by default), as flexmech's kernel time."""
    import exudyn as exu

    mbs.Assemble()
    ss = exu.SimulationSettings()
    ti = ss.timeIntegration
    ti.numberOfSteps, ti.endTime, ti.verboseMode = nsteps, t_end, 0
    ti.generalizedAlpha.spectralRadius = rho_inf
    ti.newton.relativeTolerance = 1e-8
    if absolute_tolerance is not None:
        ti.newton.absoluteTolerance = absolute_tolerance
    ss.solution.file.write = False
    ss.solution.sensors.writePeriod = write_period
    ss.show.statistics = False
    ss.show.computationTime = False
    ss.linearSolver.solverType = exu.LinearSolverType.EigenSparse
    c0 = time.thread_time()
    exu.SolveDynamic(mbs, ss)
    return time.thread_time() - c0


def smallest_times(repeats: int, run_pair):
    """run_pair() -> (flexmech result, Exudyn result) repeats times, alternating; the last results with
    each side's smallest CPU time, and all the times ([flexmech], [Exudyn])."""
    fx_cpu, ex_cpu = [], []
    for _ in range(max(1, repeats)):
        fx, ex = run_pair()
        fx_cpu.append(fx["cpu_s"]); ex_cpu.append(ex["cpu_s"])
    fx["cpu_s"], ex["cpu_s"] = min(fx_cpu), min(ex_cpu)
    return fx, ex, fx_cpu, ex_cpu


def build_exudyn(case, geometry, epl: int, masses):
    """The Exudyn system of the seed four-bar, not yet assembled: (system container, mbs, nodes per
    link, elements per link).  Every joint is a pin between link ends or a link end and the ground."""
    import exudyn as exu
    from exudyn.itemInterface import LoadCoordinate

    sc, mbs, ground, nodes, elems = cable_links(geometry, epl)
    mech = case.mechanism
    for j in mech.joints:     # pins at link ends: tied to the ground or to each other
        ends = [None if pr.body is None else nodes[mech.link_index(pr.body.name)][0 if pr.point == "start" else -1]
                for pr in mech.joint_points(j)]
        if None in ends:
            ground_pin(mbs, ground, ends[0] if ends[1] is None else ends[1])
        else:
            tie_nodes(mbs, *ends)
    for (li, end), mass in masses:
        _mass_point(mbs, nodes[li][-1 if end else 0], mass)

    root = nodes[0][0]
    ang0 = geometry[0][2]
    a, b = SEED_TORQUE

    def torque(tt):           # tau(alpha) on the root node's tangent angle alpha = atan2(s_y, s_x)
        q = mbs.GetNodeOutput(root, exu.OutputVariableType.CoordinatesTotal)
        sx, sy = q[2], q[3]
        alpha = np.arctan2(sy, sx) - ang0
        tau = a + b * np.sin(alpha)
        n2 = sx * sx + sy * sy
        return tau, sx, sy, n2

    def load_sx(mbs_, t, load):   # generalized force tau d(alpha)/d(s_x) = -tau s_y / |s|^2
        tau, sx, sy, n2 = torque(t)
        return -tau * sy / n2

    def load_sy(mbs_, t, load):
        tau, sx, sy, n2 = torque(t)
        return tau * sx / n2

    mbs.AddLoad(LoadCoordinate(markerNumber=coord_marker(mbs, root, 2), load=0.0, loadUserFunction=load_sx))
    mbs.AddLoad(LoadCoordinate(markerNumber=coord_marker(mbs, root, 3), load=0.0, loadUserFunction=load_sy))
    return sc, mbs, nodes, elems


def run_exudyn(case, geometry, epl: int, dt: float, t_end: float, rho_inf: float, masses) -> dict:
    """Exudyn's run: the midspan curvatures and the crank's root-node coordinates recorded every 10th
    step by Exudyn's own sensors (as flexmech writes every 10th frame), and the CPU time of the solve."""
    import exudyn as exu
    from exudyn.itemInterface import SensorNode

    nsteps = int(round(t_end / dt))
    sc, mbs, nodes, elems = build_exudyn(case, geometry, epl, masses)
    coupler, follower = midspan_sensors(mbs, elems, geometry, epl, (1, 2))
    root_sensor = mbs.AddSensor(SensorNode(nodeNumber=nodes[0][0], storeInternal=True,
                                           outputVariableType=exu.OutputVariableType.CoordinatesTotal))
    cpu = solve_dynamic(mbs, nsteps, t_end, rho_inf, 10 * dt)
    root = mbs.GetSensorStoredData(root_sensor)
    return {"t": root[:, 0], "strain_coupler_mid": midspan_strain(mbs, coupler, geometry[1][7]),
            "strain_follower_mid": midspan_strain(mbs, follower, geometry[2][7]), "cpu_s": cpu, "steps": nsteps,
            "crank_angle": np.unwrap(np.arctan2(root[:, 4], root[:, 3])) - geometry[0][2]}


def _seed_masses(case) -> list:
    """((link, 1 = end), mass) of the case's point masses at link ends."""
    out = []
    mech = case.mechanism
    for li, link in enumerate(mech.links):
        for frac, mass in link.lumped:
            out.append(((li, int(frac > 0.5)), float(mass)))
    return out


def relative_difference(a, b) -> float:
    """max |a - b| relative to max |a| (flexmech's peak)."""
    return float(np.max(np.abs(a - b)) / max(np.max(np.abs(a)), 1e-300))


def compare(fx: dict, ex: dict, t_max: float) -> dict:
    """Largest difference of the midspan strains over t <= t_max, relative to flexmech's peak."""
    out = {}
    for k in ("strain_coupler_mid", "strain_follower_mid"):
        t = fx["t"][fx["t"] <= t_max]
        a = fx[k][: t.size]
        out[k] = relative_difference(a, np.interp(t, ex["t"], ex[k]))
    return out


def first_revolution(fx: dict) -> float | None:
    """Time [s] at which flexmech's crank has turned by 2 pi from its start; None within the run."""
    past = np.flatnonzero(np.abs(fx["crank_angle"] - fx["crank_angle"][0]) >= 2.0 * np.pi)
    return float(fx["t"][past[0]]) if past.size else None      # the first frame past it (not sorted)


def side_by_side(case_path, epl: int = 16, dt: float = 1.25e-5, t_end: float = 0.25, rho_inf: float = 0.8,
                 t_compare: float | None = None, model: str = "nonlinear", repeats: int = 1) -> dict:
    """Both runs of the seed four-bar (flexmech's ``model``); CPU times, their ratio, the strain
    differences over t <= t_compare (default: the run) and over the crank's first revolution
    (``strain_difference_revolution``, None when the run ends before it).  With repeats > 1 the two
    runs alternate that many times and each CPU time is the smallest of its runs (the runs are
    deterministic; on a shared machine the smallest time is the one least disturbed)."""
    why = unavailable()
    if why is not None:
        return {"skipped": why}
    case = _seed_case(case_path, epl, dt, t_end, rho_inf)

    def run_pair():
        fx = run_flexmech(case, model)
        return fx, run_exudyn(case, link_geometry(case, fx["rigid"]), epl, dt, t_end, rho_inf, _seed_masses(case))

    fx, ex, fx_cpu, ex_cpu = smallest_times(repeats, run_pair)
    diff = compare(fx, ex, t_end if t_compare is None else t_compare)
    rev = first_revolution(fx)
    return {"model": model, "elements_per_link": epl, "dt": dt, "t_end": t_end, "rho_inf": rho_inf,
            "first_revolution_s": rev,
            "strain_difference_revolution": None if rev is None else compare(fx, ex, rev),
            "flexmech_cpu_s": fx["cpu_s"], "exudyn_cpu_s": ex["cpu_s"], "speedup": ex["cpu_s"] / fx["cpu_s"],
            "flexmech_cpu_s_all": fx_cpu, "exudyn_cpu_s_all": ex_cpu, "newton": fx["newton"],
            "strain_difference": diff, "flexmech": fx, "exudyn": ex}


# --------------------------------------------------------------------------------- the manipulator
def _manipulator_case(case_path, epl: int, dt: float, t_end: float, rho_inf: float):
    """The seed manipulator with its midspan strains as outputs and a frame at every step: its step
    torques ring up to tens of kHz, which frames every 10th step would fold into the low band."""
    return load_case(case_path, overrides=[
        f"solver.dt={dt!r}", f"solver.t_end={t_end!r}", "solver.output_every=1", "solver.node_angles='shared'",
        "solver.integrator='generalized-alpha'", f"solver.rho_inf={rho_inf!r}", "solver.error_estimate='none'",
        f"mesh.elements_per_link={epl}", "outputs.strain_link1_mid={kind='strain', link='link1', at=0.5}",
        "outputs.strain_link2_mid={kind='strain', link='link2', at=0.5}"])


def build_exudyn_manipulator(case, geometry, epl: int):
    """The Exudyn system of a two-link serial arm with constant joint torques (the seed manipulator),
    not yet assembled: (system container, mbs, elements per link).  Base and elbow are pins
    (coordinate constraints); a torque acts on the cable's tangent through a rigid marker
    (``MarkerBodyRigid`` + ``LoadTorqueVector``), its reaction on the inboard link's end; the mass and
    rotary inertia at link 1's end are one rigid body welded to it (``ObjectJointGeneric``), the mass
    at link 2's end a mass point."""
    from exudyn.itemInterface import (LoadTorqueVector, MarkerBodyRigid, NodeRigidBody2D, ObjectJointGeneric,
                                      ObjectRigidBody2D)

    masses = {pm["at"]: pm["mass"] for pm in case["point_masses"]}
    hubs = {ri["at"]: ri["inertia"] for ri in case["rotary_inertias"]}
    torques = {d["joint"]: d["constant"] for d in case["drives"]}
    if (len(geometry) != 2 or set(torques) != {"base", "joint_2"} or set(hubs) - {"link1.end"}
            or set(masses) - {"link1.end", "link2.end"} or any(set(d) - {"joint", "law", "constant"} for d in case["drives"])):
        raise ValueError("the Exudyn side by side models a two-link arm with constant torques at base and joint_2, "
                         "masses at the link ends and a rotary inertia at link 1's end only")
    sc, mbs, ground, nodes, elems = cable_links(geometry, epl)
    ground_pin(mbs, ground, nodes[0][0])            # base pin
    tie_nodes(mbs, nodes[0][-1], nodes[1][0])         # elbow pin

    def rigid_marker(li, end):
        return mbs.AddMarker(MarkerBodyRigid(bodyNumber=elems[li][-1 if end else 0],
                                             localPosition=[geometry[li][3] / epl if end else 0.0, 0.0, 0.0]))

    ref = mbs.GetNodeParameter(nodes[0][-1], "referenceCoordinates")
    hub = mbs.AddObject(ObjectRigidBody2D(nodeNumber=mbs.AddNode(NodeRigidBody2D(
        referenceCoordinates=[ref[0], ref[1], geometry[0][2]])), mass=masses.get("link1.end", 0.0),
        inertia=hubs.get("link1.end", 0.0)))
    hub_marker = mbs.AddMarker(MarkerBodyRigid(bodyNumber=hub, localPosition=[0.0, 0.0, 0.0]))
    mbs.AddObject(ObjectJointGeneric(markerNumbers=[rigid_marker(0, True), hub_marker], constrainedAxes=[1, 1, 0, 0, 0, 1]))
    if masses.get("link2.end", 0.0) > 0.0:
        _mass_point(mbs, nodes[1][-1], masses["link2.end"])
    mbs.AddLoad(LoadTorqueVector(markerNumber=rigid_marker(0, False), loadVector=[0.0, 0.0, torques["base"]]))
    mbs.AddLoad(LoadTorqueVector(markerNumber=rigid_marker(1, False), loadVector=[0.0, 0.0, torques["joint_2"]]))
    mbs.AddLoad(LoadTorqueVector(markerNumber=hub_marker, loadVector=[0.0, 0.0, -torques["joint_2"]]))
    return sc, mbs, elems


def run_exudyn_manipulator(case, geometry, epl: int, dt: float, t_end: float, rho_inf: float) -> dict:
    """Exudyn's run of the manipulator: midspan curvatures of both links (the mean of the two elements
    at the midspan node for even epl) at every step, CPU time of the solve."""
    nsteps = int(round(t_end / dt))
    sc, mbs, elems = build_exudyn_manipulator(case, geometry, epl)
    groups = midspan_sensors(mbs, elems, geometry, epl, (0, 1))
    cpu = solve_dynamic(mbs, nsteps, t_end, rho_inf, dt)
    out = {"t": mbs.GetSensorStoredData(groups[0][0])[:, 0], "cpu_s": cpu}
    for li, group in enumerate(groups):
        out[f"strain_link{li + 1}_mid"] = midspan_strain(mbs, group, geometry[li][7])
    return out


def low_pass(t, y, cutoff_hz: float):
    """4th-order Butterworth low-pass, forward and backward (no phase shift), of y sampled at t."""
    from scipy.signal import butter, filtfilt

    b, a = butter(4, cutoff_hz / (0.5 / (t[1] - t[0])))
    return filtfilt(b, a, y)


def manipulator_side_by_side(case_path, epl: int = 8, dt: float = 1.25e-5, t_end: float = 0.25,
                             rho_inf: float = 0.8, cutoffs=(300.0, 1000.0), repeats: int = 1) -> dict:
    """The seed manipulator in flexmech (nonlinear, shared node angles) and in Exudyn: CPU times, their
    ratio, and per cutoff [Hz] the largest difference of the low-passed midspan strains relative to
    flexmech's low-passed peak (``strain_difference[cutoff][name]``)."""
    why = unavailable()
    if why is not None:
        return {"skipped": why}
    case = _manipulator_case(case_path, epl, dt, t_end, rho_inf)

    def run_pair():
        fx = run_flexmech(case, "nonlinear", ("strain_link1_mid", "strain_link2_mid"))
        return fx, run_exudyn_manipulator(case, link_geometry(case, fx["rigid"]), epl, dt, t_end, rho_inf)

    fx, ex, fx_cpu, ex_cpu = smallest_times(repeats, run_pair)
    diff = {}
    for fc in cutoffs:
        diff[fc] = {}
        for k in ("strain_link1_mid", "strain_link2_mid"):
            diff[fc][k] = relative_difference(low_pass(fx["t"], fx[k], fc),
                                               low_pass(fx["t"], np.interp(fx["t"], ex["t"], ex[k]), fc))
    return {"elements_per_link": epl, "dt": dt, "t_end": t_end, "rho_inf": rho_inf,
            "flexmech_cpu_s": fx["cpu_s"], "exudyn_cpu_s": ex["cpu_s"], "speedup": ex["cpu_s"] / fx["cpu_s"],
            "flexmech_cpu_s_all": fx_cpu, "exudyn_cpu_s_all": ex_cpu, "strain_difference": diff,
            "flexmech": fx, "exudyn": ex}
