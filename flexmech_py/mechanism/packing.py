"""The mechanism in the flat layout of the Fortran rigid-body layer (flexmech_mbs: mbs_build).

Coordinates z = [x_C, y_C, phi] per body (the centre of mass and the frame angle; body numbering of
Mechanism.bodies); a link's frame angle is its axis angle, a rigid body's is 0 when drawn.  Every
joint contributes two markers (its points a and b); ground markers hold global positions.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .drives import Drive
from .rows import in_radians
from .system import Mechanism

__all__ = ["Packed", "Pose", "pack", "drawn_coordinates", "joint_coordinates", "joint_pose", "marker_position",
           "row_scales", "coordinate_drive", "force_constant_positions"]


@dataclass
class Packed:
    """ispec/rspec for flexmech_mbs and what Python needs to read its results."""

    ispec: np.ndarray
    rspec: np.ndarray
    n: int                      # coordinates (3 per body)
    nrow: int                   # constraint rows: joints, then kinematic drives
    nj: int
    lref: float                 # length scale [m]
    joint_rows: list            # (first row, number of rows) per joint, 0-based
    drive_rows: dict            # joint name -> row of its kinematic drive
    drives: list = field(default_factory=list)   # the drives packed (Drive objects), in order
    markers: list = field(default_factory=list)  # (body index or None, local position) per marker
    row_kinds: list = field(default_factory=list)  # the row kind (mechanism.rows) of every row
    laws_at: int = 0            # index in rspec of the first drive law's parameters


def drawn_coordinates(mech: Mechanism) -> np.ndarray:
    """z of the configuration as drawn (each body's centre of mass and frame angle)."""
    z = np.zeros(3 * len(mech.bodies))
    for i, b in enumerate(mech.bodies):
        z[3 * i:3 * i + 2] = b.centre_of_mass()
        z[3 * i + 2] = b.angle
    return z


def _marker(mech: Mechanism, ref) -> tuple:
    if ref.body is None:
        return None, np.asarray(ref.position, float)
    return mech.body_index(ref.body), ref.body.marker(ref.point)


def marker_position(z: np.ndarray, marker: tuple) -> np.ndarray:
    """Global position of a marker at coordinates z."""
    bi, s = marker
    if bi is None:
        return s
    c, sn = math.cos(z[3 * bi + 2]), math.sin(z[3 * bi + 2])
    return z[3 * bi:3 * bi + 2] + np.array([c * s[0] - sn * s[1], sn * s[0] + c * s[1]])


@dataclass(frozen=True)
class Pose:
    """A joint's two markers at one configuration: frame angles ``ang_a``, ``ang_b`` [rad], positions
    ``pa``, ``pb`` [m] (global), and a guided joint's guide direction ``axis`` in body a's frame (the
    drawn direction turned back by a's drawn angle; zeros for other kinds)."""

    ang_a: float
    ang_b: float
    pa: np.ndarray
    pb: np.ndarray
    axis: np.ndarray

    @property
    def ref(self) -> float:
        """phi_b - phi_a [rad]."""
        return self.ang_b - self.ang_a


def joint_pose(mech: Mechanism, j, z: np.ndarray) -> Pose:
    """The Pose of joint ``j`` at body coordinates z (its guide axis from the drawn configuration)."""
    a, b = mech.joint_points(j)
    ma, mb = _marker(mech, a), _marker(mech, b)
    ang = [0.0 if m[0] is None else float(z[3 * m[0] + 2]) for m in (ma, mb)]
    axis = np.zeros(2)
    if j.guided:
        axis = _rotate(j.unit_axis(), -(0.0 if a.body is None else a.body.angle))
    return Pose(ang[0], ang[1], marker_position(z, ma), marker_position(z, mb), axis)


def joint_coordinates(mech: Mechanism, z: np.ndarray, names=None) -> dict:
    """{joint: coordinate} at z: phi_b - phi_a [rad], or the slide u . (r_b - r_a) [m] of a guided
    joint (u its guide direction turning with body a)."""
    out = {}
    z0 = drawn_coordinates(mech)
    for j in mech.joints:
        if names is not None and j.name not in names:
            continue
        a, b = mech.joint_points(j)
        ma, mb = _marker(mech, a), _marker(mech, b)
        phi = lambda m: 0.0 if m[0] is None else z[3 * m[0] + 2]
        if not j.guided:
            out[j.name] = phi(mb) - phi(ma)
            continue
        rot = phi(ma) - (0.0 if ma[0] is None else z0[3 * ma[0] + 2])
        u = _rotate(j.unit_axis(), rot)
        out[j.name] = float(u @ (marker_position(z, mb) - marker_position(z, ma)))
    return out


def _rotate(v, ang: float) -> np.ndarray:
    c, s = math.cos(ang), math.sin(ang)
    return np.array([c * v[0] - s * v[1], s * v[0] + c * v[1]])


def pack(mech: Mechanism, gravity=(0.0, 0.0), starts: dict | None = None, extra_drives=(),
         kinematic_only: bool = False) -> Packed:
    """The flat description.  ``starts``: joint coordinates a kinematic law's default start refers to
    (the assembled configuration; default: as drawn); ``extra_drives``: Drive objects appended after
    the mechanism's own (assembly at given coordinates, coordinate rows for analysis);
    ``kinematic_only``: leave out the force drives."""
    z0 = drawn_coordinates(mech)
    starts = joint_coordinates(mech, z0) if starts is None else starts
    bodies = mech.bodies
    nb = len(bodies)
    markers, jt_mk, jt_coord, jt_dir, joint_rows, cr, cr_dir, cr_ref = [], [], [], [], [], [], [], []
    for ij, j in enumerate(mech.joints):
        a, b = mech.joint_points(j)
        markers += [_marker(mech, a), _marker(mech, b)]
        jt_mk.append([len(markers) - 1, len(markers)])
        pose = joint_pose(mech, j, z0)
        kind, aux, d = j.coordinate_row(pose.axis)
        jt_coord.append([kind, aux])
        jt_dir.append(d)
        rows = j.rigid_rows(pose)
        joint_rows.append((len(cr), len(rows)))
        for kind, aux, d, value in rows:
            cr.append([ij + 1, kind, aux])
            cr_dir.append(d)
            cr_ref.append(value)
    row_kinds = [r[1] for r in cr]
    row = len(cr)
    drives = [d for d in mech.drives if not (kinematic_only and not d.kinematic)] + list(extra_drives)
    names = [j.name for j in mech.joints]
    packed_laws = [d.packed(starts[d.joint]) for d in drives]
    nh = max([max(len(k["sin"]), len(k["cos"])) for k in packed_laws] + [0])
    nth = max([len(k["time_harmonics"]) for k in packed_laws] + [0])
    tab_t, tab_c, dv_tab, drive_rows = [], [], [], {}
    for d, k in zip(drives, packed_laws):
        if d.kinematic:
            drive_rows[d.joint] = row
            row_kinds.append(jt_coord[names.index(d.joint)][0])
            row += 1
        if k["table"] is None:
            dv_tab.append([0, 0])
        else:
            dv_tab.append([len(tab_t) + 1, len(k["table"][0])])
            tab_t += list(k["table"][0])
            tab_c += list(k["table"][1].T)
    lref = mech.characteristic_length()
    mass = [b.mass_properties() for b in bodies]
    ispec = [nb, len(markers), len(mech.joints), len(drives), len(tab_t), nh, nth, len(cr)]
    ispec += [0 if m[0] is None else m[0] + 1 for m in markers]
    ispec += [i for pair in jt_mk for i in pair] + [i for pair in jt_coord for i in pair] + [i for r in cr for i in r]
    ispec += [names.index(d.joint) + 1 for d in drives] + [d.code for d in drives]
    ispec += [i for pair in dv_tab for i in pair]
    rspec = [m for m, _, _ in mass] + [j for _, _, j in mass] + [float(gravity[0]), float(gravity[1]), lref]
    rspec += [x for m in markers for x in m[1]]
    rspec += [float(x) for d in jt_dir for x in d] + [float(x) for d in cr_dir for x in d] + [float(v) for v in cr_ref]
    laws_at = len(rspec)
    for k in packed_laws:
        rspec += list(k["par"])
    for k in packed_laws:
        rspec += list(k["sin"]) + [0.0] * (nh - len(k["sin"])) + list(k["cos"]) + [0.0] * (nh - len(k["cos"]))
    for k in packed_laws:
        th = list(k["time_harmonics"]) + [[0.0, 0.0, 0.0]] * (nth - len(k["time_harmonics"]))
        rspec += [x for h in th for x in h]
    rspec += tab_t + [x for c in tab_c for x in c]
    return Packed(ispec=np.array(ispec, np.int32), rspec=np.array(rspec, float), n=3 * nb, nrow=row,
                  nj=len(mech.joints), lref=lref, joint_rows=joint_rows, drive_rows=drive_rows, drives=drives,
                  markers=markers, row_kinds=row_kinds, laws_at=laws_at)


def force_constant_positions(packed: Packed) -> dict:
    """{joint: index in packed.rspec} of the ``constant`` of every force drive (the first of its law's
    four parameters, which flexmech_drivelaw adds to the effort at every evaluation): a caller that
    changes it there changes the effort from the next evaluation on (flexmech_py.run.stepping)."""
    return {d.joint: packed.laws_at + 4 * k for k, d in enumerate(packed.drives) if not d.kinematic}


def row_scales(mech: Mechanism, packed: Packed) -> np.ndarray:
    """(nrow,) length per unit of each constraint row: 1 for rows in metres, lref for rows in radians."""
    return np.array([packed.lref if in_radians(k) else 1.0 for k in packed.row_kinds])


def coordinate_drive(joint: str, value: float) -> Drive:
    """A drive holding a joint coordinate at ``value`` (a row for assembly and analysis)."""
    return Drive(joint=joint, law="constant_speed", params={"speed": 0.0, "start": float(value)})
