"""Dormand-Prince 8(5,3) explicit Runge-Kutta (DOP853) with its 7th-order dense output.

A NumPy transcription of the algorithm and step-size control of SciPy's ``solve_ivp(method="DOP853")``
(scipy/integrate/_ivp/rk.py, common.py; the coefficients are those of scipy's dop853_coefficients.py,
from E. Hairer's DOP853 code; SciPy is BSD-3-licensed), so the rigid-body motion is the same to round-off
while ``import scipy.integrate`` (about 0.3-0.5 s of start-up, most of a short run) is not needed.
E. Hairer, S. P. Norsett, G. Wanner, "Solving Ordinary Differential Equations I", Sec. II.5 and II.6.
"""

from __future__ import annotations

import numpy as np

__all__ = ["dop853", "DenseSolution"]

N_STAGES = 12
N_STAGES_EXTENDED = 16
INTERPOLATOR_POWER = 7

C = np.array([0.0, 0.05260015195876773, 0.0789002279381516, 0.1183503419072274, 0.2816496580927726, 0.3333333333333333, 0.25, 0.3076923076923077, 0.6512820512820513, 0.6, 0.8571428571428571, 1.0, 1.0, 0.1, 0.2, 0.7777777777777778])
A = np.zeros((N_STAGES_EXTENDED, N_STAGES_EXTENDED))
A[1, 0] = 0.05260015195876773
A[2, 0] = 0.0197250569845379
A[2, 1] = 0.0591751709536137
A[3, 0] = 0.02958758547680685
A[3, 2] = 0.08876275643042054
A[4, 0] = 0.2413651341592667
A[4, 2] = -0.8845494793282861
A[4, 3] = 0.924834003261792
A[5, 0] = 0.037037037037037035
A[5, 3] = 0.17082860872947386
A[5, 4] = 0.12546768756682242
A[6, 0] = 0.037109375
A[6, 3] = 0.17025221101954405
A[6, 4] = 0.06021653898045596
A[6, 5] = -0.017578125
A[7, 0] = 0.03709200011850479
A[7, 3] = 0.17038392571223998
A[7, 4] = 0.10726203044637328
A[7, 5] = -0.015319437748624402
A[7, 6] = 0.008273789163814023
A[8, 0] = 0.6241109587160757
A[8, 3] = -3.3608926294469414
A[8, 4] = -0.868219346841726
A[8, 5] = 27.59209969944671
A[8, 6] = 20.154067550477894
A[8, 7] = -43.48988418106996
A[9, 0] = 0.47766253643826434
A[9, 3] = -2.4881146199716677
A[9, 4] = -0.590290826836843
A[9, 5] = 21.230051448181193
A[9, 6] = 15.279233632882423
A[9, 7] = -33.28821096898486
A[9, 8] = -0.020331201708508627
A[10, 0] = -0.9371424300859873
A[10, 3] = 5.186372428844064
A[10, 4] = 1.0914373489967295
A[10, 5] = -8.149787010746927
A[10, 6] = -18.52006565999696
A[10, 7] = 22.739487099350505
A[10, 8] = 2.4936055526796523
A[10, 9] = -3.0467644718982196
A[11, 0] = 2.273310147516538
A[11, 3] = -10.53449546673725
A[11, 4] = -2.0008720582248625
A[11, 5] = -17.9589318631188
A[11, 6] = 27.94888452941996
A[11, 7] = -2.8589982771350235
A[11, 8] = -8.87285693353063
A[11, 9] = 12.360567175794303
A[11, 10] = 0.6433927460157636
A[12, 0] = 0.054293734116568765
A[12, 5] = 4.450312892752409
A[12, 6] = 1.8915178993145003
A[12, 7] = -5.801203960010585
A[12, 8] = 0.3111643669578199
A[12, 9] = -0.1521609496625161
A[12, 10] = 0.20136540080403034
A[12, 11] = 0.04471061572777259
A[13, 0] = 0.056167502283047954
A[13, 6] = 0.25350021021662483
A[13, 7] = -0.2462390374708025
A[13, 8] = -0.12419142326381637
A[13, 9] = 0.15329179827876568
A[13, 10] = 0.00820105229563469
A[13, 11] = 0.007567897660545699
A[13, 12] = -0.008298
A[14, 0] = 0.03183464816350214
A[14, 5] = 0.028300909672366776
A[14, 6] = 0.053541988307438566
A[14, 7] = -0.05492374857139099
A[14, 10] = -0.00010834732869724932
A[14, 11] = 0.0003825710908356584
A[14, 12] = -0.00034046500868740456
A[14, 13] = 0.1413124436746325
A[15, 0] = -0.42889630158379194
A[15, 5] = -4.697621415361164
A[15, 6] = 7.683421196062599
A[15, 7] = 4.06898981839711
A[15, 8] = 0.3567271874552811
A[15, 12] = -0.0013990241651590145
A[15, 13] = 2.9475147891527724
A[15, 14] = -9.15095847217987
B = A[N_STAGES, :N_STAGES]
E3 = np.array([-0.18980075407240762, 0.0, 0.0, 0.0, 0.0, 4.450312892752409, 1.8915178993145003, -5.801203960010585, -0.4226823213237919, -0.1521609496625161, 0.20136540080403034, 0.02265179219836082, 0.0])
E5 = np.array([0.01312004499419488, 0.0, 0.0, 0.0, 0.0, -1.2251564463762044, -0.4957589496572502, 1.6643771824549864, -0.35032884874997366, 0.3341791187130175, 0.08192320648511571, -0.022355307863886294, 0.0])
D = np.array([
    [-8.428938276109013, 0.0, 0.0, 0.0, 0.0, 0.5667149535193777, -3.0689499459498917, 2.38466765651207, 2.117034582445028, -0.871391583777973, 2.2404374302607883, 0.6315787787694688, -0.08899033645133331, 18.148505520854727, -9.194632392478356, -4.436036387594894],
    [10.427508642579134, 0.0, 0.0, 0.0, 0.0, 242.28349177525817, 165.20045171727028, -374.5467547226902, -22.113666853125306, 7.733432668472264, -30.674084731089398, -9.332130526430229, 15.697238121770845, -31.139403219565178, -9.35292435884448, 35.81684148639408],
    [19.985053242002433, 0.0, 0.0, 0.0, 0.0, -387.0373087493518, -189.17813819516758, 527.8081592054236, -11.57390253995963, 6.8812326946963, -1.0006050966910838, 0.7777137798053443, -2.778205752353508, -60.19669523126412, 84.32040550667716, 11.99229113618279],
    [-25.69393346270375, 0.0, 0.0, 0.0, 0.0, -154.18974869023643, -231.5293791760455, 357.6391179106141, 93.40532418362432, -37.45832313645163, 104.0996495089623, 29.8402934266605, -43.53345659001114, 96.32455395918828, -39.17726167561544, -149.72683625798564]])
A_EXTRA, C_EXTRA = A[N_STAGES + 1:], C[N_STAGES + 1:]
A_STEP, C_STEP = A[:N_STAGES, :N_STAGES], C[:N_STAGES]
SAFETY, MIN_FACTOR, MAX_FACTOR = 0.9, 0.2, 10.0
ERROR_EXPONENT = -1.0 / 8.0       # -1 / (error estimator order 7 + 1)
EPS = np.finfo(float).eps


def _rms(x):
    return np.linalg.norm(x) / x.size ** 0.5


def _initial_step(fun, t0, y0, t_bound, f0, rtol, atol, order=7):
    """Hairer-Norsett-Wanner initial step (scipy common.select_initial_step, max_step = inf, forward)."""
    interval_length = abs(t_bound - t0)
    scale = atol + np.abs(y0) * rtol
    d0, d1 = _rms(y0 / scale), _rms(f0 / scale)
    h0 = 1e-6 if d0 < 1e-5 or d1 < 1e-5 else 0.01 * d0 / d1
    h0 = min(h0, interval_length)
    f1 = fun(t0 + h0, y0 + h0 * f0)
    d2 = _rms((f1 - f0) / scale) / h0
    if d1 <= 1e-15 and d2 <= 1e-15:
        h1 = max(1e-6, h0 * 1e-3)
    else:
        h1 = (0.01 / max(d1, d2)) ** (1 / (order + 1))
    return min(100 * h0, h1, interval_length)


class DenseSolution:
    """The piecewise 7th-order interpolant of a DOP853 solution: ``sol(t)`` (n, N) for times t (N,)."""

    def __init__(self, t_old, h, y_old, F):
        self.t_old, self.h, self.y_old, self.F = np.array(t_old), np.array(h), np.array(y_old), np.array(F)
        self.t_end = self.t_old + self.h

    def __call__(self, t):
        t = np.asarray(t, dtype=float)
        seg = np.searchsorted(self.t_end, t, side="left")   # as scipy's OdeSolution: the step ending at t
        seg = np.clip(seg, 0, self.h.size - 1)
        x = ((t - self.t_old[seg]) / self.h[seg])[:, None]
        F = self.F[seg]                                      # (N, 7, n)
        y = np.zeros((t.size, self.y_old.shape[1]))
        for i in range(INTERPOLATOR_POWER):
            y += F[:, INTERPOLATOR_POWER - 1 - i]
            if i % 2 == 0:
                y *= x
            else:
                y *= 1 - x
        y += self.y_old[seg]
        return y.T


def dop853(fun, t0, y0, t_bound, rtol, atol, event=None):
    """Integrate y' = fun(t, y) from (t0, y0) to t_bound.

    event(t, y): optional terminal event, active when it goes from >= 0 to <= 0 (located by bisection
    on the dense output to 4 eps).  Returns (status, solution, t_event, y_event, message): status 0 at
    t_bound, 1 at the event, -1 when the step size became too small."""
    y = np.asarray(y0, dtype=float).copy()
    n, t = y.size, float(t0)
    K_ext = np.empty((N_STAGES_EXTENDED, n))
    K = K_ext[:N_STAGES + 1]
    f = fun(t, y)
    h_abs = _initial_step(fun, t, y, t_bound, f, rtol, atol)
    t_olds, hs, y_olds, Fs = [], [], [], []
    g = event(t, y) if event is not None else None
    while t < t_bound:
        min_step = 10 * np.abs(np.nextafter(t, np.inf) - t)
        h_abs = max(h_abs, min_step)
        rejected = False
        while True:
            if h_abs < min_step:
                return -1, None, t, y, "the step size became too small"
            t_new = t + h_abs
            if t_new - t_bound > 0:
                t_new = t_bound
            h = t_new - t
            h_abs = np.abs(h)
            K[0] = f
            for s in range(1, N_STAGES):
                dy = np.dot(K[:s].T, A_STEP[s, :s]) * h
                K[s] = fun(t + C_STEP[s] * h, y + dy)
            y_new = y + h * np.dot(K[:-1].T, B)
            f_new = fun(t + h, y_new)
            K[-1] = f_new
            scale = atol + np.maximum(np.abs(y), np.abs(y_new)) * rtol
            err5 = np.dot(K.T, E5) / scale
            err3 = np.dot(K.T, E3) / scale
            e5, e3 = np.linalg.norm(err5) ** 2, np.linalg.norm(err3) ** 2
            err = 0.0 if e5 == 0 and e3 == 0 else np.abs(h) * e5 / np.sqrt((e5 + 0.01 * e3) * n)
            if err < 1:
                factor = MAX_FACTOR if err == 0 else min(MAX_FACTOR, SAFETY * err ** ERROR_EXPONENT)
                if rejected:
                    factor = min(1, factor)
                h_abs *= factor
                break
            h_abs *= max(MIN_FACTOR, SAFETY * err ** ERROR_EXPONENT)
            rejected = True
        # dense output of the step (three extra stages)
        for s, (a, c) in enumerate(zip(A_EXTRA, C_EXTRA), start=N_STAGES + 1):
            K_ext[s] = fun(t + c * h, y + np.dot(K_ext[:s].T, a[:s]) * h)
        F = np.empty((INTERPOLATOR_POWER, n))
        dlt = y_new - y
        F[0] = dlt
        F[1] = h * K_ext[0] - dlt
        F[2] = 2 * dlt - h * (f_new + K_ext[0])
        F[3:] = h * np.dot(D, K_ext)
        t_olds.append(t); hs.append(h); y_olds.append(y); Fs.append(F)
        t, y, f = t_new, y_new, f_new
        if event is not None:
            g_new = event(t, y)
            if g >= 0 and g_new <= 0:
                step = DenseSolution([t_olds[-1]], [hs[-1]], [y_olds[-1]], [F])
                lo, hi = t_olds[-1], t
                while hi - lo > 4 * EPS * max(abs(hi), 1.0):
                    mid = 0.5 * (lo + hi)
                    if event(mid, step(np.array([mid]))[:, 0]) > 0:
                        lo = mid
                    else:
                        hi = mid
                return 1, DenseSolution(t_olds, hs, y_olds, Fs), hi, step(np.array([hi]))[:, 0], "event"
            g = g_new
    return 0, DenseSolution(t_olds, hs, y_olds, Fs), None, None, "done"
