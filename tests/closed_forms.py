"""Closed-form kinematics of the four-bar and the slider-crank, written out independently of
flexmech's constraint-based mechanism layer, to test it against (textbook vector-loop solutions)."""

import math

import numpy as np


def fourbar_angles(a, b, c, d, th2, branch=1):
    """Coupler and follower angles (th3, th4) of the four-bar O2 = (0, 0), O4 = (d, 0), crank a at th2:
    B is where the circles about A (radius b) and O4 (radius c) meet; branch +1 puts B to the left of
    A -> O4 (the open branch for a crank-rocker at th2 = 0)."""
    ax, ay = a * math.cos(th2), a * math.sin(th2)
    dx, dy = d - ax, -ay
    r = math.hypot(dx, dy)
    ell = (b * b - c * c + r * r) / (2 * r)
    h = branch * math.sqrt(b * b - ell * ell)
    bx, by = ax + (ell * dx - h * dy) / r, ay + (ell * dy + h * dx) / r
    return math.atan2(by - ay, bx - ax), math.atan2(by, bx - d)


def fourbar_rates(a, b, c, th2, th3, th4, w2, al2):
    """(w3, w4, al3, al4) from the loop a e2 + b e3 - c e4 - d = 0 differentiated once and twice."""
    w3 = a * w2 * math.sin(th4 - th2) / (b * math.sin(th3 - th4))
    w4 = a * w2 * math.sin(th2 - th3) / (c * math.sin(th4 - th3))
    # a (al2 Om e2 - w2^2 e2) + b (al3 Om e3 - w3^2 e3) - c (al4 Om e4 - w4^2 e4) = 0, linear in al3, al4
    e = lambda th: np.array([math.cos(th), math.sin(th)])
    om = lambda th: np.array([-math.sin(th), math.cos(th)])
    rhs = -(a * (al2 * om(th2) - w2 ** 2 * e(th2)) - b * w3 ** 2 * e(th3) + c * w4 ** 2 * e(th4))
    al3, al4 = np.linalg.solve(np.column_stack([b * om(th3), -c * om(th4)]), rhs)
    return w3, w4, al3, al4


def slider_crank(r, l, th, w, al, e=0.0):
    """Slider position, velocity and acceleration along X (crank r about the origin at th, coupler l,
    slider pin at height e), and the coupler angle."""
    s = r * math.sin(th) - e
    sd = r * w * math.cos(th)
    sdd = r * al * math.cos(th) - r * w * w * math.sin(th)
    cc = math.sqrt(l * l - s * s)
    x = r * math.cos(th) + cc
    xd = -r * w * math.sin(th) - s * sd / cc
    xdd = -r * al * math.sin(th) - r * w * w * math.cos(th) - (sd * sd + s * sdd) / cc - (s * sd) ** 2 / cc ** 3
    return x, xd, xdd, math.atan2(-s, cc)
