"""An error term defined at the top of a module, as a robot file can name it."""

import casadi as ca

from casecal.model.parameters import UNITS, Unit

UNITS.setdefault("m/K", Unit("µm/K", 1e6, 1e-3, 1e-5, 1e-3))


def a2_growth(ctx, term):
    """a2 grows by k_a2 per kelvin from 20 °C: a transform after link 2."""
    T = ca.SX.eye(4)
    T[0, 3] = ctx.p("k_a2") * (ctx.inputs["temperature_c"] - 20.0)
    return T
