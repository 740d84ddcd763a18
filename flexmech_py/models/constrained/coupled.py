"""The one-pass coupled model (seed Section 3) and the nonlinear model on any planar mechanism:
rigid and elastic coordinates in one system (docs/theory.md sections 11-12).

:class:`CoupledModel` is a case's model: its layout (segments, rigid bodies, markers, constraint rows
and force drives: :mod:`flexmech_py.models.constrained.layout`), its state on the rigid-body solution, the
values of its constraint rows, and the calls of the compiled kernel (fortran/flexmech_coupled_*.f90).
Outputs and diagnostics of a run: :mod:`flexmech_py.models.constrained.outputs`.
"""

from __future__ import annotations

import numpy as np

from ...base import kernels
from ...case import DIVERGENCE_FACTOR
from ...mechanism.control import ControlPack, pack_controllers
from .layout import (CON_ANGLE, CON_POINT, CON_PROJECTION, MK_NODE, Layout, LinkMesh, Row, SharedAngles,
                     flat_description, force_constant_positions, marker_key, node_segment, start_value)

__all__ = ["CoupledModel", "LinkMesh", "validity", "CON_POINT", "CON_ANGLE", "CON_PROJECTION", "SOLVER_PATHS"]

#: the linear algebra of a Newton step (fortran/flexmech_coupled_solve.f90: PATH_*)
SOLVER_PATHS = ("band, multipliers by their Schur complement", "saddle band",
                "condensed segments, multipliers by their Schur complement", "bordered saddle band")


class CoupledModel:
    """The coupled (``split=False``: one segment per flexible link) or nonlinear (``split=True``: one
    per element) model of a resolved case; build with :meth:`from_case`.

    Attributes (from the :class:`~flexmech_py.models.constrained.layout.Layout`): ``segments`` (link, k0, k1),
    ``n_el``, ``ld`` (maxld, nseg) 1-based all-DOF numbers of each segment's local vector, ``ndof``,
    ``free_of`` (1-based, 0 = fixed), ``q_fixed``, ``bodies``, ``markers``, ``rows``, ``joints``
    {name: JointModel}, ``forces``, ``mesh`` (the flexible links' mesh view for results);
    ``last_run`` the last run's frames and final state; ``solver`` the structure of its linear algebra
    (:meth:`structure`, taken at a run's start)."""

    def __init__(self, layout: Layout):
        self.layout = layout
        self.case, self.split, self.mesh, self.fracs = layout.case, layout.split, layout.mesh, layout.fracs
        self.segments, self.n_el, self.ld = layout.segments, layout.n_el, layout.ld
        self.ndof, self.free_of, self.q_fixed = len(layout.dof), layout.free_of, layout.q_fixed
        self.bodies, self.markers, self.rows = layout.bodies, layout.markers, layout.rows
        self.joints, self.forces, self.node_ends = layout.joints, layout.forces, layout.node_ends
        self.last_run = None
        self.solver = None
        self._flat = None
        self._kflat = None
        self._by_link = None      # {link: (segment numbers, their end nodes k1)}, built on first use
        #: the nonlinear model with solver.node_angles = "shared": the kernel integrates one absolute
        #: angle per node (coupled_layout.SharedAngles); None: chord-relative angles and weld rows
        shared = layout.split and layout.case["solver"].get("node_angles", "relative") == "shared"
        self.shared = SharedAngles.of(layout) if shared else None

    @classmethod
    def from_case(cls, case: dict, split: bool = False, hold_forced: bool = False) -> "CoupledModel":
        """The model of a resolved case (``hold_forced``: see :class:`~flexmech_py.models.constrained.layout.Layout`)."""
        cm = cls(Layout(case, split, hold_forced))
        for name, sp in case["outputs"].items():   # points must be markers the model can follow
            if isinstance(sp.get("at"), str):
                cm.output_marker(sp["at"], f"outputs.{name}.at")
        return cm

    # ------------------------------------------------------------------ layout helpers
    def seg_slice(self, si: int) -> np.ndarray:
        """0-based all-DOF numbers of segment si's local vector (length 3n+3)."""
        return self.ld[: 3 * self.n_el[si] + 3, si] - 1

    def link_ends(self, li: int) -> tuple[np.ndarray, np.ndarray]:
        """0-based DOF pairs (x, y) of the start and end node of flexible link li."""
        segs = [si for si, sg in enumerate(self.segments) if sg[0] == li]
        return self.seg_slice(segs[0])[0:2], self.seg_slice(segs[-1])[2:4]

    def node_segment(self, li: int, k: int) -> tuple[int, int]:
        """(segment, node within it) of mesh node k of link li: the first segment holding it (a
        bisection: the nonlinear model has a segment per element, and outputs ask for every node)."""
        segs, ends = self._link_segments(li)
        si = segs[min(int(np.searchsorted(ends, k, side="left")), len(segs) - 1)]
        if not self.segments[si][1] <= k <= self.segments[si][2]:
            return node_segment(self.segments, li, k)       # (raises: k is not on the link)
        return si, k - self.segments[si][1]

    def element_segment(self, li: int, e: int) -> tuple[int, int]:
        """(segment, element within it) of element e (0-based, along the link) of link li."""
        segs, ends = self._link_segments(li)
        si = segs[min(int(np.searchsorted(ends, e, side="right")), len(segs) - 1)]
        return si, e - self.segments[si][1]

    def _link_segments(self, li: int) -> tuple[list[int], np.ndarray]:
        if self._by_link is None:
            by = {}
            for si, (l2, _, k1) in enumerate(self.segments):   # (a link's segments in order along it)
                by.setdefault(l2, ([], []))
                by[l2][0].append(si)
                by[l2][1].append(k1)
            self._by_link = {l2: (sg, np.asarray(ends)) for l2, (sg, ends) in by.items()}
        return self._by_link[li]

    def body_of(self, bi: int):
        """The rigid-body entry (index, DOFs, m, J_C, J_S) of mechanism body bi (None for a flexible link)."""
        return next((b for b in self.bodies if b[0] == bi), None)

    def output_marker(self, ref: str, where: str) -> int:
        """Index of the marker at a point reference of a body (added to the markers when new)."""
        key = marker_key(self, self.case.mechanism.point(ref, where), where)
        if key not in self.markers:
            self.markers.append(key)
            self._flat = None
        return self.markers.index(key)

    @property
    def nfree(self) -> int:
        return int(self.free_of.max())

    # ------------------------------------------------------------------ states
    def initial_state(self, rm0) -> tuple[np.ndarray, np.ndarray]:
        """All-DOF (q, v) at rest elastically, on the configuration of the first sample of the rigid
        motion rm0 (nodes on the rigid links, rigid bodies at their coordinates)."""
        return self.rigid_state(rm0)[:2]

    def rigid_state(self, rm, i: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """All-DOF (q, v, a) of the rigid motion's sample i, undeformed (elastic DOFs and their rates
        zero): segment ends on the rigid links with their rigid velocities and accelerations, rigid
        bodies at their coordinates."""
        km = rm.motion
        q, v, a = self.q_fixed.copy(), np.zeros(self.ndof), np.zeros(self.ndof)
        for si, (li, k0, k1) in enumerate(self.segments):
            L = self.case["links"][li]["length"]
            c, s = np.cos(km.phi[i, li]), np.sin(km.phi[i, li])
            w, al = km.omega[i, li], km.alpha[i, li]
            dofs = self.seg_slice(si)
            pos, vel, acc = [], [], []
            for k in (k0, k1):
                x = self.fracs[li][k] * L
                pos += [km.ox[i, li] + x * c, km.oy[i, li] + x * s]
                vel += [km.vx[i, li] - w * x * s, km.vy[i, li] + w * x * c]
                acc += [km.ax[i, li] - al * x * s - w * w * x * c, km.ay[i, li] + al * x * c - w * w * x * s]
            for k in range(4):
                if self.free_of[dofs[k]] > 0:
                    q[dofs[k]], v[dofs[k]], a[dofs[k]] = pos[k], vel[k], acc[k]
        for bi, dofs, *_ in self.bodies:
            q[dofs], v[dofs], a[dofs] = (x[i, 3 * bi:3 * bi + 3] for x in (rm.z, rm.zd, rm.zdd))
        return q, v, a

    def constraint_values(self, rm, start=None) -> np.ndarray:
        """(3, max(1, nc), nt) [value, rate, acceleration] of the rows on the rigid motion's grid: the
        drive law (the rigid joint coordinate) for a kinematic drive, the initial value for a held
        coordinate (a weld, a locked joint, a guided joint's relative angle), zero otherwise.
        ``start``: the rigid motion whose first sample holds the initial values (default ``rm``; a
        later chunk of a run passes its first chunk, so held values stay those of t = 0)."""
        start = rm if start is None else start
        out = np.zeros((3, max(1, len(self.rows)), rm.t.size))
        for i, r in enumerate(self.rows):
            if r.value[0] == "drive":
                out[:, i] = rm.joint(r.value[1]).T
            elif r.value[0] == "start":
                out[0, i] = start_value(self.case.mechanism, start, r.value[1], r.value[2])
            elif r.value[0] == "rigid":
                out[0, i] = self._own_row_value(rm, r)
        return np.asfortranarray(out)

    def set_force_constants(self, values: dict) -> None:
        """Set the ``constant`` [N m or N] of the force drives of the joints in ``values`` in the flat
        descriptions the kernels read: the runs and evaluations after the call apply it."""
        self._spec((0.0, 0.0), (0.0, 0.0))
        self._spec((0.0, 0.0), (0.0, 0.0), kernel=True)
        for ispec, rspec in {id(f): f for f in (self._flat, self._kflat) if f is not None}.values():
            pos = force_constant_positions(self.layout, rspec.size, ispec)
            for joint, value in values.items():
                rspec[pos[joint]] = float(value)

    def _own_row_value(self, rm, r) -> np.ndarray:
        """(nt,) the value of a kind's own row (Joint.own_rows) on the rigid motion, its frame angles
        taken as the model's markers take them: a segment node's wrapped to (-pi, pi] (the chord's
        atan2), a body's and a shared absolute node angle's as they are (flexmech_markers
        con_residual reduces what is left across the cut)."""
        mech = self.case.mechanism
        j = mech.joint(r.value[1])
        pts = mech.joint_points(j)
        ang = []
        for p, m in zip(pts, (r.a, r.b)):
            x = np.zeros(rm.t.size) if p.body is None else rm.z[:, 3 * mech.body_index(p.body) + 2]
            if self.markers[m][0] == MK_NODE and self.shared is None:
                x = np.angle(np.exp(1j * x))
            ang.append(x)
        return j.held_values(r.value[2], *ang, *(rm.point_positions(p) for p in pts))

    # ------------------------------------------------------------------ kernel calls
    def _spec(self, gravity, rayleigh, kernel=False):
        """The flat description with gravity [m/s^2] and Rayleigh damping [1/s, s]; ``kernel``: the one
        the time integration runs on (the nonlinear model's shared node angles)."""
        if kernel and self.shared is not None:
            if self._kflat is None:
                self._kflat = flat_description(self.layout, shared=self.shared)
            ispec, rspec = self._kflat
        else:
            if self._flat is None:
                self._flat = flat_description(self.layout)
            ispec, rspec = self._flat
        rspec = rspec.copy()
        rspec[-4:] = [gravity[0], gravity[1], rayleigh[0], rayleigh[1]]
        return ispec, rspec

    def kernel_inputs(self, dt: float, gravity=(0.0, 0.0), rayleigh=(0.0, 0.0), div_limit=None) -> "KernelInputs":
        """What :meth:`run` hands the kernel that does not change between the calls of one run (built
        once by a caller that runs it call by call; see :class:`KernelInputs`)."""
        return KernelInputs(self, dt, gravity, rayleigh, div_limit)

    def run(self, q0, v0, t, cval, dt, *, beta=0.25, gamma=0.5, alpha_m=0.0, alpha_f=0.0, out_every=1, tol=1e-8,
            maxit=25, gravity=(0.0, 0.0), rayleigh=(0.0, 0.0), p0=None, div_limit=None, t0=None, state=None,
            inputs=None):
        """Generalized-alpha-Newton run over the grid t (Newmark (beta, gamma) for ``alpha_m = alpha_f
        = 0``; see :func:`flexmech_py.case.integrator_coefficients`); returns (qf, vf, af, lf, ef,
        iterations).  cval: constraint_values() on t.  ``p0`` (ndof): the pseudo-acceleration to start
        from (None: p0 = the consistent initial acceleration).  ``state``: the ``last_run`` of the run
        this one continues (its ``q, v, a, p, carry, cst``, copied; q0, v0 and p0 are then not used):
        the steps are those of one uninterrupted run.  ``div_limit`` [m]: the divergence guard (default
        DIVERGENCE_FACTOR x the longest flexible link).  ``inputs``: :meth:`kernel_inputs` built once
        for this dt, gravity, rayleigh and div_limit (then those four are not read).  After the call
        ``self.last_run`` holds the frames, ``la`` (nc, nframes) the multipliers' largest step-to-step
        alternating part since the last frame (fortran/flexmech_alternation.f90), ``frames_valid``, the
        final state ``q, v, a, p, carry, cst``, ``status`` and ``fail_step`` (also when the run failed)."""
        kin = self.kernel_inputs(dt, gravity, rayleigh, div_limit) if inputs is None else inputs
        t0 = float(t[0]) if t0 is None else float(t0)
        if state is not None:
            start = 2
            q, v, a, p, carry, cst = (np.array(state[k], float, order="F") for k in ("q", "v", "a", "p", "carry", "cst"))
        else:
            start = 1 if p0 is None else 0
            q, v, a = np.array(q0, float), np.array(v0, float), np.zeros(self.ndof)
            p = np.zeros(self.ndof) if p0 is None else np.array(p0, float)
            if self.shared is not None:
                q, v, p = self.shared.to_kernel(q, v, p)
            carry, cst = np.zeros(max(1, kin.keep.size) + 2), kin.ctl.cst.copy(order="F")
            self.solver = self._structure(kin.ispec, kin.rspec, q, v)  # (a continued run keeps its start's)
        ctl = kin.ctl
        qf, vf, af, lk, lka, ef, uf, status, fail, iters, nvalid, newton = kernels.cpl.cpl_run(
            kin.ispec, kin.rspec, kin.kernel_values(cval), t0, dt, alpha_m, alpha_f, beta, gamma,
            out_every, tol, maxit, start, kin.div_limit, kin.seg_link, q, v, a, p, carry,
            ctl.cint, ctl.cpar, ctl.ctab_t, ctl.ctab_c, cst)
        lf, la = kin.all_rows(lk), kin.all_rows(lka)      # the interior welds of shared node angles carry none
        if self.shared is not None:         # the valid frames (a failed run leaves zeros after them)
            qf[:, :nvalid], vf[:, :nvalid], af[:, :nvalid] = self.shared.from_kernel(
                qf[:, :nvalid], vf[:, :nvalid], af[:, :nvalid])
        self.last_run = {"qf": qf, "vf": vf, "af": af, "lf": lf, "la": la, "ef": ef, "frames_valid": int(nvalid),
                         "q": q, "v": v, "a": a, "p": p, "carry": carry, "status": int(status), "fail_step": int(fail),
                         "factorizations": int(newton[3]), "cst": cst,
                         "controls": {n: uf[k] for k, n in enumerate(ctl.names)}}
        if status != 0:
            detail = ""
            if status == kernels.STATUS_NEWTON:
                detail = (f" (last iteration: residual norm {newton[0]:.3g}, acceleration correction "
                          f"{newton[1]:.3g} against accelerations of norm {newton[2]:.3g})")
            kernels.check_status(status, "coupled time integration", time=t0 + fail * dt if fail else t0,
                                 detail=detail, step=int(fail),
                                 data={"qf": qf, "vf": vf, "af": af, "lf": lf, "ef": ef, "iters": iters,
                                       "q": q, "v": v, "a": a, "p": p, "newton": newton})
        return qf, vf, af, lf, ef, iters

    def controllers(self, dt: float) -> ControlPack:
        """The case's feedback controllers packed for a run with step dt (flexmech_control)."""
        mech = self.case.mechanism
        revolute = {j.name for j in mech.joints if j.angular}
        return pack_controllers(self.case.get("controllers", []), [d.joint for _, d in self.forces], revolute, dt,
                                self.layout.control_rows, self.layout.control_scales)

    def control_outputs(self, nf: int) -> dict:
        """{controller: (nf,) its output [N m or N]} over the first nf frames of the last run."""
        return {n: u[:nf].copy() for n, u in (self.last_run or {}).get("controls", {}).items()}

    def control_effort(self, joint: str, nf: int) -> np.ndarray:
        """(nf,) the summed outputs of the controllers acting on ``joint`` over the last run's first nf frames."""
        out = np.zeros(nf)
        for c in self.case.get("controllers", []):
            if c["joint"] == joint:
                out += self.last_run["controls"][c["name"]][:nf]
        return out

    def structure(self, q, v) -> dict:
        """The linear algebra a run takes at the state (q, v) (all DOFs, the layout's angles), with the
        solver modes set now (kernels.cpl.cpl_set_solver, cpl_set_multipliers): ``path`` (one of
        :data:`SOLVER_PATHS`), ``band_unknowns`` and ``band_half_width`` of its band, ``dense_unknowns``
        (the border, or the rows of a Schur complement), and the floating-point operations of one
        factorization and of one solve (machine-independent: their growth with the mesh shows a
        quadratic cost; docs/theory.md section 12.6)."""
        ispec, rspec = self._spec((0.0, 0.0), (0.0, 0.0), kernel=True)
        q, v = np.asarray(q, float), np.asarray(v, float)
        if self.shared is not None:
            q, v, _ = self.shared.to_kernel(q, v, np.zeros_like(q))
        return self._structure(ispec, rspec, q, v)

    @staticmethod
    def _structure(ispec, rspec, q, v) -> dict:
        info, status = kernels.cpl.cpl_structure(ispec, rspec, q, v)
        kernels.check_status(status, "cpl_structure")
        return {"path": SOLVER_PATHS[int(info[0])], "band_unknowns": int(info[1]), "band_half_width": int(info[2]),
                "dense_unknowns": int(info[3]), "flops_per_factorization": float(info[4]),
                "flops_per_solve": float(info[5])}

    def dense(self, q, v, a, gravity=(0.0, 0.0), rayleigh=(0.0, 0.0), t=0.0):
        """Residual (all DOFs, no constraint forces), M, C_v, K_t (dense, free DOFs), [kinetic,
        potential] energy at one state and time."""
        ispec, rspec = self._spec(gravity, rayleigh)
        res, mm, cm, km, energy, status = kernels.cpl.cpl_dense(
            self.nfree, ispec, rspec, np.asarray(q, float), np.asarray(v, float), np.asarray(a, float), float(t))
        kernels.check_status(status, "cpl_dense")
        return res, mm, cm, km, energy

    def residuals(self, qs, v, a, t=0.0, gravity=(0.0, 0.0), rayleigh=(0.0, 0.0)) -> np.ndarray:
        """(ndof, ns) residuals (as :meth:`dense`) at the configurations qs (ndof, ns), every one with
        the velocities v and accelerations a (ndof), at time t [s]."""
        ispec, rspec = self._spec(gravity, rayleigh)
        res, status = kernels.cpl.cpl_residuals(ispec, rspec, np.asfortranarray(qs, float), np.asarray(v, float),
                                                np.asarray(a, float), float(t))
        kernels.check_status(status, "cpl_residuals")
        return res

    def row_values(self, qs, v=None) -> tuple[np.ndarray, np.ndarray]:
        """Values (nc, ns) of the constraint rows (angles not wrapped) and their gradients (nc, ndof, ns)
        over all DOFs at the configurations qs (ndof, ns)."""
        ispec, rspec = self._spec((0.0, 0.0), (0.0, 0.0))
        qs = np.asfortranarray(qs, float)
        nc = len(self.rows)
        g, gq, status = kernels.cpl.cpl_rows(max(1, nc), ispec, rspec, qs,
                                             np.zeros(self.ndof) if v is None else np.asarray(v, float))
        kernels.check_status(status, "cpl_rows")
        return g[:nc], gq[:nc]

    def post(self, qf, vf, af, lf, tf, measures, gravity=(0.0, 0.0), rayleigh=(0.0, 0.0)) -> dict:
        """Frames evaluated on the model (flexmech_coupled_post): ``markers`` (9, nmk, nf)
        [x, y, psi, rates, accelerations] of every marker, ``measures`` (3, nm, nf) [value, rate,
        acceleration] of the measure Rows, ``forces`` (nd, nf) the force drives' values, ``ends``
        (4, nseg, nf) the segment-end residuals (joint forces through shared DOFs)."""
        ispec, rspec = self._spec(gravity, rayleigh, kernel=True)
        if self.shared is not None:
            qf, vf, af = self.shared.to_kernel(qf, vf, af)
            lf = lf[self.shared.keep]
        meas = list(measures) or [Row(CON_POINT, 0, 0, 1)]
        mi = np.asfortranarray(np.array([[r.kind, r.a + 1, r.b + 1, r.aux] for r in meas], np.int32).T)
        md = np.asfortranarray(np.array([r.d for r in meas], float).T)
        nc1 = max(1, len(self.rows))
        lfull = np.zeros((nc1, qf.shape[1]), order="F")
        lfull[:lf.shape[0]] = lf
        mks, mv, dvals, rend, status = kernels.cpl.cpl_post(
            len(self.markers), max(1, len(self.forces)), len(self.segments), ispec, rspec,
            np.asfortranarray(qf), np.asfortranarray(vf), np.asfortranarray(af), lfull, np.asarray(tf, float), mi, md)
        kernels.check_status(status, "cpl_post")
        return {"markers": mks, "measures": mv[:, :len(measures)], "forces": dvals[:len(self.forces)], "ends": rend}


class KernelInputs:
    """The arguments of the coupled kernel's run (kernels.cpl.cpl_run) that stay the same from call to
    call of one run: the flat description with gravity and damping (``ispec``, ``rspec``), the
    divergence limit [m], each segment's link (``seg_link``), the constraint rows the kernel keeps
    (``keep``) and the controllers' pack (``ctl``, its ``cst`` the state a fresh run starts from)."""

    def __init__(self, cm: CoupledModel, dt: float, gravity, rayleigh, div_limit):
        self.nc = len(cm.rows)
        self.keep = np.arange(self.nc) if cm.shared is None else cm.shared.keep
        self.ispec, self.rspec = cm._spec(gravity, rayleigh, kernel=True)
        if div_limit is None:
            div_limit = DIVERGENCE_FACTOR * max(cm.case["links"][li]["length"] for li, _, _ in cm.segments)
        self.div_limit = float(div_limit)
        self.seg_link = np.array([li + 1 for li, _, _ in cm.segments], np.int32)
        self.ctl = cm.controllers(dt)
        self.positions = force_constant_positions(cm.layout, self.rspec.size, self.ispec)
        self._all = self.keep.size == self.nc > 0       # the kernel's rows are the model's

    def set_force_constants(self, values: dict) -> None:
        """As :meth:`CoupledModel.set_force_constants`, in this description."""
        for joint, value in values.items():
            self.rspec[self.positions[joint]] = float(value)

    def kernel_values(self, cval) -> np.ndarray:
        """(3, max(1, kept rows), nt) the constraint values (CoupledModel.constraint_values) of the
        rows the kernel keeps, Fortran-ordered (cval itself when it is all of them)."""
        if self._all or self.nc == 0:
            return np.asfortranarray(cval, float)
        kval = np.zeros((3, max(1, self.keep.size), cval.shape[2]), order="F")
        kval[:, :self.keep.size] = np.asarray(cval)[:, self.keep]
        return kval

    def all_rows(self, lk: np.ndarray) -> np.ndarray:
        """(nc, nframes) a kernel's per-row frames (kept rows) on all the model's rows (zeros elsewhere)."""
        if self._all:
            return lk
        if self.nc == 0:
            return lk[:0]
        out = np.zeros((self.nc, lk.shape[1]))
        out[self.keep] = lk[:self.keep.size]
        return out


def validity(fe, axial: np.ndarray, u_dev: np.ndarray) -> dict:
    """Per flexible link: the largest compressive and tensile axial force over the Euler load
    pi^2 EI / L^2 of the link, and the largest displacement from the rigid motion over its length."""
    out = {}
    for li, ln in enumerate(fe.case["links"]):
        if ln.get("rigid"):
            continue
        ne = np.pi ** 2 * ln["youngs_modulus"] * ln["second_moment"] / ln["length"] ** 2
        n = axial[fe.link_elements(li)]
        disp = max(float(np.max(np.hypot(u_dev[fe.trans_dof[node, 0]], u_dev[fe.trans_dof[node, 1]])))
                   for node in fe.node_of[li])
        out[ln["name"]] = {"euler_load_N": ne, "max_compression_over_euler": float(max(0.0, -n.min()) / ne),
                           "max_tension_over_euler": float(max(0.0, n.max()) / ne),
                           "max_displacement_over_length": disp / ln["length"]}
    return out
