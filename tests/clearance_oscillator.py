"""The clearance (backlash) oscillator shared by the continuation and completion tests,
and its independent reference by SciPy's integrator.

x'' + 0.1 x' + g(x) = 0.1 + 0.03 cos(w t), with g(x) = x - clip(x, -1, 1): unit
stiffness outside a clearance of +-1, a hysteresis band between the folds near
w = 0.6365 and 0.852 rad/s (pyHarm and NLvib agree on them).
"""

import numpy as np
import scipy.integrate

import gearjax as gj


def oscillator():
    """The oscillator as a one-coordinate ``System`` (forcing harmonic 1 of the base)."""
    return gj.system_from_matrices([[1.0]], [[0.1]], [[0.0]], [[1.0]], [1.0], backlash=[1.0],
                                   f_mean=[0.1], f_cos=[[0.03]], f_sin=[[0.0]],
                                   forcing_mu=[1])


def ivp_amplitude(omega, z0, periods=80):
    """Independent reference: the half peak-to-peak amplitude of x over the last of
    ``periods`` forcing periods, integrated by SciPy (RK45, rtol 1e-10) from ``z0``
    ``(x, x')``."""
    def rhs(t, z):
        x, v = z
        return [v, 0.1 + 0.03 * np.cos(omega * t) - 0.1 * v - (x - np.clip(x, -1, 1))]

    P = 2 * np.pi / omega
    sol = scipy.integrate.solve_ivp(rhs, (0, periods * P), z0, rtol=1e-10, atol=1e-12,
                                    t_eval=np.linspace((periods - 1) * P, periods * P, 2001))
    return (sol.y[0].max() - sol.y[0].min()) / 2
