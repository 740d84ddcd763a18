"""Side by side with Exudyn on a multi-loop mechanism (issue 30; docs/performance.md, "Side by side
with Exudyn").

A case's mechanism of flexible links, rigid bodies and revolute joints at link ends and body points,
driven at constant speed at a ground pivot of a flexible link (cases/sixbar_plate.toml: a Stephenson
six-bar, two loops sharing a rigid ternary plate), built in Exudyn the way
:mod:`flexmech_py.studies.bench_exudyn` builds the seed four-bar: every flexible link as ANCF cable elements
(``ObjectANCFCable2D``) on the nodes of flexmech's mesh, a rigid body as ``ObjectRigidBody2D``, a pin
between two link ends as coordinate constraints, a pin at a body point as ``ObjectJointRevolute2D``.
The drive acts without a Python callback on either side: in flexmech a kinematic row on the joint
angle, in Exudyn a massless hub welded to the crank's root (``ObjectJointGeneric``) whose angle
velocity a velocity-level ``CoordinateConstraint`` holds at the drive's speed.  Both start on the
rigid-body motion of the first sample (positions and velocities), elastically at rest; both give
the midspan bending strains (curvature x the half depth), compared over the run, and the CPU time of
the time integration (model building not counted on either side).
"""

from __future__ import annotations

import numpy as np

from .bench_exudyn import (cable_links, coord_marker, ground_pin, link_geometry, midspan_sensors, midspan_strain,
                           relative_difference, run_flexmech, smallest_times, solve_dynamic, tie_nodes, unavailable)
from ..case import load_case

__all__ = ["mechanism_case", "build_exudyn_mechanism", "run_exudyn_mechanism", "mechanism_side_by_side"]

#: the midspan strains compared (outputs of cases/sixbar_plate.toml) and the links they are on
STRAINS = {"strain_rocker_mid": "rocker", "strain_cd_mid": "link_cd"}
#: Exudyn's Newton: absolute tolerance of the residual per coordinate [N] besides the relative 1e-8.  A
#: mechanism driven through a constraint has no load to scale the relative test by, and its iteration
#: stagnates at 1e-8..1e-7 relative and halves the step without end: from 16 elements per link with
#: no absolute tolerance, at 32 with 1e-6 (measured: 25 iterations at 6e-8..8e-8 relative, the step
#: halved to 2.4e-8 s, 70 000 steps to reach t = 2.4 ms).  1e-4 lies in the range Exudyn's own hint
#: gives for such systems (1e-5..1e-2); the strains compared show what it costs (docs/performance.md)
EXUDYN_ABSOLUTE_TOLERANCE = 1e-4


def mechanism_case(case_path, epl: int, dt: float, t_end: float, rho_inf: float, node_angles: str = "relative"):
    """The case run for t_end with steps dt, generalized-alpha rho_inf, epl elements per link, no
    error estimate, frames every 10th step."""

    return load_case(case_path, overrides=[f"solver.dt={dt!r}", f"solver.t_end={t_end!r}", "solver.output_every=10",
                                           f"solver.node_angles={node_angles!r}", "solver.integrator='generalized-alpha'",
                                           f"solver.rho_inf={rho_inf!r}", "solver.error_estimate='none'",
                                           f"mesh.elements_per_link={epl}"])


def _supported(mech) -> None:
    """ValueError unless the mechanism is what this builder models."""
    if any(ln.rigid for ln in mech.links) or any(j.kind != "revolute" for j in mech.joints):
        raise ValueError("the Exudyn side by side models flexible links, rigid bodies and revolute joints only")
    if len(mech.drives) != 1 or mech.drives[0].law != "constant_speed":
        raise ValueError("the Exudyn side by side models one constant-speed drive")


class _Builder:
    """The Exudyn items of one mechanism (see the module's docstring)."""

    def __init__(self, case, rm, epl: int):
        from exudyn.itemInterface import NodeRigidBody2D, ObjectGround, ObjectRigidBody2D

        self.case, self.mech, self.epl = case, case.mechanism, epl
        _supported(self.mech)
        self.geometry = link_geometry(case, rm)
        km = rm.motion
        rates = [(float(km.vx[0, li]), float(km.vy[0, li]), float(km.omega[0, li])) for li in range(len(self.geometry))]
        self.sc, self.mbs, self.ground, self.nodes, self.elems = cable_links(self.geometry, epl, rates)
        self.ground_body = self.mbs.AddObject(ObjectGround(referencePosition=[0.0, 0.0, 0.0]))
        self.bodies = {}
        for bi, body in enumerate(self.mech.bodies):
            if body.kind == "link":
                continue
            node = self.mbs.AddNode(NodeRigidBody2D(referenceCoordinates=list(rm.z[0, 3 * bi:3 * bi + 3]),
                                                    initialVelocities=list(rm.zd[0, 3 * bi:3 * bi + 3])))
            m, _, jc = body.mass_properties()
            self.bodies[body.name] = (self.mbs.AddObject(ObjectRigidBody2D(mass=m, inertia=jc,
                                                                           nodeNumber=node)), body)

    def link_node(self, pr):
        """The cable node at a flexible link's end point (None for another point)."""
        li = self.mech.link_index(pr.body.name)
        frac = pr.body.fraction(pr.point)
        return self.nodes[li][0] if frac == 0.0 else self.nodes[li][-1] if frac == 1.0 else None

    def position_marker(self, pr):
        """A position marker at a resolved point: a cable end node, a body point or a ground point."""
        from exudyn.itemInterface import MarkerBodyPosition, MarkerNodePosition

        if pr.body is None:
            return self.mbs.AddMarker(MarkerBodyPosition(bodyNumber=self.ground_body,
                                                         localPosition=[*map(float, pr.position), 0.0]))
        if pr.body.kind == "link":
            node = self.link_node(pr)
            if node is None:
                raise ValueError(f"the Exudyn side by side joins links at their ends only, not at {pr.label}")
            return self.mbs.AddMarker(MarkerNodePosition(nodeNumber=node))
        obj, body = self.bodies[pr.body.name]
        return self.mbs.AddMarker(MarkerBodyPosition(bodyNumber=obj, localPosition=[*map(float, body.marker(pr.point)), 0.0]))

    def joint(self, j) -> None:
        """A revolute joint: coordinate constraints between cable nodes (or a node and the ground), a
        revolute pair at a body point."""
        from exudyn.itemInterface import ObjectJointRevolute2D

        a, b = self.mech.joint_points(j)
        ends = [None if pr.body is None else self.link_node(pr) if pr.body.kind == "link" else False for pr in (a, b)]
        if all(e not in (None, False) for e in ends):
            tie_nodes(self.mbs, *ends)
        elif ends[0] is None and ends[1] not in (None, False):
            ground_pin(self.mbs, self.ground, ends[1])
        elif ends[1] is None and ends[0] not in (None, False):
            ground_pin(self.mbs, self.ground, ends[0])
        else:
            self.mbs.AddObject(ObjectJointRevolute2D(markerNumbers=[self.position_marker(a), self.position_marker(b)]))

    def drive(self, rm) -> None:
        """The constant-speed drive: a massless hub welded to the driven link's root, its angle velocity
        held by a velocity-level coordinate constraint (no user function)."""
        from exudyn.itemInterface import (CoordinateConstraint, MarkerBodyRigid, NodeRigidBody2D, ObjectJointGeneric,
                                          ObjectRigidBody2D)

        d = self.mech.drives[0]
        a, b = self.mech.joint_points(self.mech.joint(d.joint))
        if (a.body is None) == (b.body is None):
            raise ValueError("the Exudyn side by side drives a joint between the ground and a link's root")
        link = b if a.body is None else a
        sign = 1.0 if a.body is None else -1.0       # the joint angle is b's relative to a's
        li = self.mech.link_index(link.body.name)
        if link.body.fraction(link.point) != 0.0:
            raise ValueError("the Exudyn side by side drives a link at its start")
        x0, y0, ang = self.geometry[li][:3]
        speed = sign * float(d.params["speed"])
        hub_node = self.mbs.AddNode(NodeRigidBody2D(referenceCoordinates=[x0, y0, ang], initialVelocities=[0.0, 0.0, speed]))
        hub = self.mbs.AddObject(ObjectRigidBody2D(mass=0.0, inertia=0.0, nodeNumber=hub_node))
        root = self.mbs.AddMarker(MarkerBodyRigid(bodyNumber=self.elems[li][0], localPosition=[0.0, 0.0, 0.0]))
        hub_marker = self.mbs.AddMarker(MarkerBodyRigid(bodyNumber=hub, localPosition=[0.0, 0.0, 0.0]))
        self.mbs.AddObject(ObjectJointGeneric(markerNumbers=[root, hub_marker], constrainedAxes=[1, 1, 0, 0, 0, 1]))
        self.mbs.AddObject(CoordinateConstraint(markerNumbers=[coord_marker(self.mbs, self.ground, 0),
                                                               coord_marker(self.mbs, hub_node, 2)],
                                                offset=speed, velocityLevel=True))


def build_exudyn_mechanism(case, rm, epl: int):
    """The Exudyn system of the case's mechanism on the rigid motion rm's first sample, not yet
    assembled: (system container, mbs, nodes per link, elements per link, link geometry)."""
    bld = _Builder(case, rm, epl)
    for j in bld.mech.joints:
        bld.joint(j)
    bld.drive(rm)
    return bld.sc, bld.mbs, bld.nodes, bld.elems, bld.geometry


def run_exudyn_mechanism(case, rm, epl: int, dt: float, t_end: float, rho_inf: float) -> dict:
    """Exudyn's run: the midspan strains of STRAINS every 10th step, the CPU time of the solve."""
    nsteps = int(round(t_end / dt))
    sc, mbs, nodes, elems, geometry = build_exudyn_mechanism(case, rm, epl)
    names = [ln.name for ln in case.mechanism.links]
    links = [names.index(link) for link in STRAINS.values()]
    groups = midspan_sensors(mbs, elems, geometry, epl, links)
    cpu = solve_dynamic(mbs, nsteps, t_end, rho_inf, 10 * dt, EXUDYN_ABSOLUTE_TOLERANCE)
    out = {"t": mbs.GetSensorStoredData(groups[0][0])[:, 0], "cpu_s": cpu, "steps": nsteps}
    for key, li, group in zip(STRAINS, links, groups):
        out[key] = midspan_strain(mbs, group, geometry[li][7])
    return out


def mechanism_side_by_side(case_path, epl: int = 16, dt: float = 1.25e-5, t_end: float = 0.05, rho_inf: float = 0.8,
                           node_angles: str = "relative", repeats: int = 1) -> dict:
    """Both runs of the case (flexmech's nonlinear model with the given node angles): CPU times of the
    time integration, their ratio (with repeats > 1 alternating, each side's smallest), and the
    largest difference of the midspan strains over the run relative to flexmech's peak."""
    why = unavailable()
    if why is not None:
        return {"skipped": why}
    case = mechanism_case(case_path, epl, dt, t_end, rho_inf, node_angles)

    def run_pair():
        fx = run_flexmech(case, "nonlinear", tuple(STRAINS))
        return fx, run_exudyn_mechanism(case, fx["rigid"], epl, dt, t_end, rho_inf)

    fx, ex, fx_cpu, ex_cpu = smallest_times(repeats, run_pair)
    diff = {k: relative_difference(fx[k], np.interp(fx["t"], ex["t"], ex[k])) for k in STRAINS}
    return {"elements_per_link": epl, "node_angles": node_angles, "dt": dt, "t_end": t_end, "rho_inf": rho_inf,
            "flexmech_cpu_s": fx["cpu_s"], "exudyn_cpu_s": ex["cpu_s"], "speedup": ex["cpu_s"] / fx["cpu_s"],
            "flexmech_cpu_s_all": fx_cpu, "exudyn_cpu_s_all": ex_cpu, "newton": fx["newton"],
            "strain_difference": diff, "flexmech": fx, "exudyn": ex}
