"""Process units around the mill: feed source, holding tank, classifier, PI controller.

Plain numpy cores, no FMI: ``step(h, **inputs) -> None`` advances by h [s] with inputs held
over the step; ``outputs()`` gives the values at the end of the last step; ``get_state`` /
``set_state`` return and take plain (JSON-able) copies. The FMI adapters are in
:mod:`unit_fmu`. SI units; size distributions are class mass fractions [-] on the mill's
size grid (ascending sizes).

Convention for mass flows [kg/s] (the same as the mill FMU's ``product_mass_flow``): a
flow output is the mean over the last completed step, so the mass a unit discharged over
that step is flow * step. Each step's outflow is computed as (content before) + (inflow)
- (content after), so every unit conserves solids mass to round-off.
"""

from __future__ import annotations

import math

import numpy as np

try:  # carried into a unit FMU, the grid module sits next to this one
    from .grid import characteristic_sizes_m, checked_fractions
except ImportError:  # in the repository it is millfmu's
    from millfmu.kinetics.grid import characteristic_sizes_m, checked_fractions


class UnitInputError(ValueError):
    """Bad input or parameter: names it, gives the value and what is allowed. State unchanged."""

    def __init__(self, name: str, value, allowed: str):
        self.name, self.value, self.allowed = name, value, allowed
        super().__init__(f"{name} = {value!r}: {allowed}")


class StepDiscarded(RuntimeError):
    """The unit refuses this step (the master may retry with a smaller one). State unchanged."""


def _x50(edges_m, psd) -> float:
    class _G:  # characteristic_sizes_m needs only the edges
        pass

    g = _G()
    g.edges_m = edges_m
    return characteristic_sizes_m(g, psd, (0.5,))[0]


def _check_flow(name, x):
    if not (math.isfinite(x) and 0.0 <= x <= 1e3):
        raise UnitInputError(name, x, "must lie in [0, 1000] kg/s")


def _check_fraction(name, x, lo_open=True):
    if not (math.isfinite(x) and (0.0 < x if lo_open else 0.0 <= x) and x < 1.0):
        raise UnitInputError(name, x, "must lie in (0, 1)" if lo_open else "must lie in [0, 1)")


def _split_psd(masses: np.ndarray, fallback: np.ndarray) -> np.ndarray:
    """Class mass fractions of ``masses`` (``fallback`` where there is no mass)."""
    tot = float(masses.sum())
    return masses / tot if tot > 0.0 else fallback.copy()


# ---------------------------------------------------------------------------------------
class Feed:
    """Feed source: solids mass flow [kg/s] piecewise linear in time (steps and ramps) and a
    size distribution that changes stepwise.

    profile: list of (t_s, mass_flow_kg_per_s), times non-decreasing; two points at one time
    make a step; constant before the first and after the last point.
    psd_segments: list of (t_s, fractions): from t_s on, the feed has these fractions.
    solids_mass_fraction [-]: of the fed suspension.
    event_tolerance_s: > 0 makes the feed refuse a step that holds a jump of its profile
    (mass flow or size distribution) more than this before the step's end, so a master that
    retries smaller steps places the jump at a step boundary (event location by bisection);
    0: off.
    The mean flow over a step is the exact integral of the profile over the step / step.
    """

    def __init__(self, edges_m, profile, psd_segments, solids_mass_fraction, event_tolerance_s=0.0):
        self.edges_m = np.asarray(edges_m, float)
        self.n = len(self.edges_m) - 1
        self.profile = [(float(t), float(m)) for t, m in profile]
        self.psd_segments = [(float(t), np.asarray(w, float)) for t, w in psd_segments]
        self.solids_mass_fraction = float(solids_mass_fraction)
        self.event_tolerance_s = float(event_tolerance_s)
        self.jumps = sorted({t for (t, _), (t2, _) in zip(self.profile, self.profile[1:]) if t == t2}
                            | {t for t, _ in self.psd_segments[1:]})
        self.reset()

    def reset(self):
        self.t_s = 0.0
        self.fed_kg = 0.0
        self._flow = 0.0
        self._psd = self._psd_at(0.0)

    def _psd_at(self, t):
        w = self.psd_segments[0][1]
        for t0, ww in self.psd_segments:
            if t >= t0:
                w = ww
        return w

    def _integral(self, t):
        """Integral of the mass flow from 0 to t [kg] (exact for the piecewise linear profile)."""
        p = self.profile
        total = 0.0
        if t <= p[0][0]:
            return p[0][1] * t
        total += p[0][1] * p[0][0]
        for (t0, m0), (t1, m1) in zip(p, p[1:]):
            if t <= t0:
                break
            if t1 > t0:
                te = min(t, t1)
                mt = m0 + (m1 - m0) * (te - t0) / (t1 - t0)
                total += 0.5 * (m0 + mt) * (te - t0)
        if t > p[-1][0]:
            total += p[-1][1] * (t - p[-1][0])
        return total

    def step(self, h):
        t0, t1 = self.t_s, self.t_s + h
        tol = self.event_tolerance_s
        if tol > 0.0:
            for tj in self.jumps:
                if t0 < tj < t1 - tol:
                    raise StepDiscarded(f"step [{t0!r}, {t1!r}] s holds a jump of the feed at t = {tj!r} s "
                                        f"more than event_tolerance_s = {tol!r} s before its end")
        # Mass per class over the step: the flow integral within each psd segment.
        cuts = [t0] + [t for t, _ in self.psd_segments[1:] if t0 < t < t1] + [t1]
        masses = np.zeros(self.n)
        for a, b in zip(cuts, cuts[1:]):
            masses += (self._integral(b) - self._integral(a)) * self._psd_at(0.5 * (a + b))
        total = float(masses.sum())
        self._flow = total / h
        self._psd = _split_psd(masses, self._psd_at(t1))
        self.fed_kg += total
        self.t_s = t1

    def outputs(self):
        return {"mass_flow": self._flow, "solids_mass_fraction": self.solids_mass_fraction, "psd": self._psd,
                "x50": _x50(self.edges_m, self._psd), "mass_total": self.fed_kg}

    def get_state(self):
        return {"t_s": self.t_s, "fed_kg": self.fed_kg, "flow": self._flow, "psd": self._psd.tolist()}

    def set_state(self, s):
        self.t_s, self.fed_kg, self._flow = float(s["t_s"]), float(s["fed_kg"]), float(s["flow"])
        self._psd = np.array(s["psd"], float)


# ---------------------------------------------------------------------------------------
class Tank:
    """Perfectly mixed stirred holding tank with two inlets and a pumped outlet.

    State: solids mass per class M_i [kg] and suspension mass S [kg] (solids + liquid).
    Inlet k brings solids at m_k [kg/s] with class fractions w_k and solids mass fraction
    c_k, i.e. suspension at m_k / c_k. The pump draws suspension at p [kg/s] (from
    ``pump_start_s`` on, while the tank holds suspension). With inputs held over a step,
    S(t) = S0 + (a - p) t (a: suspension inflow) and, perfectly mixed,
    dM_i/dt = u_i - p M_i / S, whose exact solution is used:
    M_i(t) = M0_i (S0/S)^(p/k) + (u_i/a) (S - S0 (S0/S)^(p/k)), k = a - p != 0, and
    M_i(t) = M0_i e^(-p t/S0) + u_i S0/p (1 - e^(-p t/S0)) for k = 0.
    If the tank would run dry within the step, it ends the step empty (the rest passes
    through). The solids outflow over a step is M(0) + u h - M(h), class by class.

    Level control (a sump in a closed circuit): with ``level_setpoint_kg`` > 0 the pump
    draws p = max(0, a + (S0 - S_set) / tau) over each step (proportional level control
    with time constant ``level_time_constant_s``, S0 at the step's start), instead of the
    fixed ``pump_mass_flow_kg_per_s``.
    """

    def __init__(self, edges_m, initial_solids_kg, initial_solids_mass_fraction, initial_psd, pump_mass_flow_kg_per_s,
                 pump_start_s=0.0,
                 level_setpoint_kg=0.0, level_time_constant_s=60.0):
        self.edges_m = np.asarray(edges_m, float)
        self.n = len(self.edges_m) - 1
        self.m0_kg = float(initial_solids_kg)
        self.c0 = float(initial_solids_mass_fraction)
        self.psd0 = np.asarray(initial_psd, float)
        self.pump = float(pump_mass_flow_kg_per_s)
        self.pump_start_s = float(pump_start_s)
        self.level_setpoint_kg = float(level_setpoint_kg)
        self.level_time_constant_s = float(level_time_constant_s)
        self.reset()

    def reset(self):
        self.t_s = 0.0
        self.M = self.m0_kg * self.psd0
        self.S = self.m0_kg / self.c0 if self.m0_kg > 0 else 0.0
        self._out_flow = 0.0
        self._out_psd = _split_psd(self.M, self.psd0)
        self.in_kg = 0.0
        self.out_kg = 0.0

    def step(self, h, inflow=((0.0, 0.5, None), (0.0, 0.5, None))):
        """inflow: per inlet (solids mass flow [kg/s], solids mass fraction [-], class fractions)."""
        u = np.zeros(self.n)
        a = 0.0
        for k, (m, c, w) in enumerate(inflow, 1):
            _check_flow(f"inlet{k}_mass_flow", m)
            _check_fraction(f"inlet{k}_solids_mass_fraction", c)
            if m > 0.0:
                u += m * checked_fractions(f"inlet{k}_psd", w, self.n, UnitInputError)
                a += m / c
        S0, M0 = self.S, self.M
        if self.t_s < self.pump_start_s:
            p = 0.0
        elif self.level_setpoint_kg > 0.0:
            p = max(0.0, a + (S0 - self.level_setpoint_kg) / self.level_time_constant_s)
        else:
            p = self.pump
        k = a - p
        S1 = S0 + k * h
        if p > 0.0 and S1 <= 1e-12 * max(S0, 1.0):  # runs dry: everything held and fed leaves
            M1, S1 = np.zeros(self.n), 0.0
        elif p == 0.0:
            M1 = M0 + u * h
        elif S0 <= 0.0:  # fills from empty while pumping (k > 0): S = k t, M = u S / a
            M1 = (u / a) * S1
        elif abs(k) <= 1e-15 * p:
            e = math.exp(-p * h / S0)
            M1 = M0 * e + u * (S0 / p) * (-math.expm1(-p * h / S0))
        else:
            # r = (S0/S1)^(p/k), as exp(-(p/k) log1p(k h/S0)): the plain power loses digits
            # when inflow and pump nearly balance (p/k large, S0/S1 near 1), as in a circuit.
            r = math.exp(-(p / k) * math.log1p(k * h / S0))
            M1 = M0 * r + (u / a) * (S1 - S0 * r) if a > 0.0 else M0 * r
        M1 = np.maximum(M1, 0.0)
        out = M0 + u * h - M1
        out = np.maximum(out, 0.0)  # round-off below zero: keep the balance on M1 instead
        M1 = M0 + u * h - out
        self.M, self.S = M1, max(S1, 0.0)
        tot_out = float(out.sum())
        self._out_flow = tot_out / h
        self._out_psd = _split_psd(out, _split_psd(self.M, self._out_psd))
        self.in_kg += float(u.sum()) * h
        self.out_kg += tot_out
        self.t_s += h

    @property
    def solids_mass_fraction(self):
        tot = float(self.M.sum())
        return tot / self.S if self.S > 0.0 and tot > 0.0 else self.c0

    def outputs(self):
        content = _split_psd(self.M, self._out_psd)
        return {"outflow_mass_flow": self._out_flow, "solids_mass_fraction": self.solids_mass_fraction,
                "psd": self._out_psd,
                "holdup": float(self.M.sum()), "suspension_mass": self.S, "x50": _x50(self.edges_m, content)}

    def get_state(self):
        return {"t_s": self.t_s, "M": self.M.tolist(), "S": self.S, "out_flow": self._out_flow,
                "out_psd": self._out_psd.tolist(),
                "in_kg": self.in_kg, "out_kg": self.out_kg, "pump": self.pump}

    def set_state(self, s):
        self.t_s, self.S, self._out_flow = float(s["t_s"]), float(s["S"]), float(s["out_flow"])
        self.M, self._out_psd = np.array(s["M"], float), np.array(s["out_psd"], float)
        self.in_kg, self.out_kg, self.pump = float(s["in_kg"]), float(s["out_kg"]), float(s["pump"])


# ---------------------------------------------------------------------------------------
def tromp(x_m, cut_size_m, sharpness, bypass):
    """Tromp curve: fraction of class x that goes to the coarse stream [-].

    T(x) = bypass + (1 - bypass) / (1 + (x_cut/x)^kappa): ``bypass`` is the fraction of the
    feed that reaches the coarse stream unclassified (fines in the coarse product), kappa the
    sharpness (x25/x75 of the classifying part = 3^(-2/kappa)); T(x_cut) = bypass + (1 - bypass)/2.
    """
    x = np.asarray(x_m, float)
    return bypass + (1.0 - bypass) / (1.0 + (cut_size_m / x) ** sharpness)


class Classifier:
    """Classifier without holdup: splits the inflow by the Tromp curve :func:`tromp`, class by
    class at the class's representative size (geometric mean of its edges). The liquid
    splits with ``liquid_to_coarse`` [-] to the coarse stream."""

    def __init__(self, edges_m, cut_size_m, sharpness, bypass, liquid_to_coarse):
        self.edges_m = np.asarray(edges_m, float)
        self.n = len(self.edges_m) - 1
        self.x_m = np.sqrt(self.edges_m[:-1] * self.edges_m[1:])
        self.liquid_to_coarse = float(liquid_to_coarse)
        self.set_parameters(cut_size_m, sharpness, bypass)
        self.reset()

    def set_parameters(self, cut_size_m, sharpness, bypass):
        self.cut_size_m, self.sharpness, self.bypass = float(cut_size_m), float(sharpness), float(bypass)
        self.T = tromp(self.x_m, self.cut_size_m, self.sharpness, self.bypass)

    def reset(self):
        self.t_s = 0.0
        self.await_feed(np.full(self.n, 1.0 / self.n))
        self.in_kg = 0.0

    def await_feed(self, psd):
        """Before anything has flowed: both streams empty, their size distributions the split
        of ``psd`` (the feed expected, class mass fractions), so that their x50 at t = 0 is the
        split's and not that of an arbitrary distribution."""
        w = np.asarray(psd, float)
        self._c = {"coarse": (0.0, 0.5, _split_psd(self.T * w, w)),
                   "fine": (0.0, 0.5, _split_psd((1 - self.T) * w, w))}

    def step(self, h, mass_flow, solids_mass_fraction, psd):
        _check_flow("feed_mass_flow", mass_flow)
        _check_fraction("feed_solids_mass_fraction", solids_mass_fraction)
        w = checked_fractions("feed_psd", psd, self.n, UnitInputError)
        m_in = mass_flow * w
        coarse = self.T * m_in
        fine = m_in - coarse  # exact complement: the split conserves mass class by class
        liquid = mass_flow * (1.0 - solids_mass_fraction) / solids_mass_fraction
        res = {}
        for name, m, liq in (("coarse", coarse, liquid * self.liquid_to_coarse),
                             ("fine", fine, liquid * (1.0 - self.liquid_to_coarse))):
            tot = float(m.sum())
            c = tot / (tot + liq) if tot > 0.0 and tot + liq > 0.0 else self._c[name][1]
            res[name] = (tot, min(c, 0.999), _split_psd(m, self._c[name][2]))
        self._c = res
        self.in_kg += mass_flow * h
        self.t_s += h

    def outputs(self):
        out = {}
        for name, (m, c, w) in self._c.items():
            out[f"{name}_mass_flow"] = m
            out[f"{name}_solids_mass_fraction"] = c
            out[f"{name}_psd"] = w
            out[f"{name}_x50"] = _x50(self.edges_m, w)
        return out

    def get_state(self):
        return {"t_s": self.t_s, "in_kg": self.in_kg, "c": {k: [m, c, w.tolist()] for k, (m, c, w) in self._c.items()},
                "par": [self.cut_size_m, self.sharpness, self.bypass]}

    def set_state(self, s):
        self.t_s, self.in_kg = float(s["t_s"]), float(s["in_kg"])
        self._c = {k: (float(m), float(c), np.array(w, float)) for k, (m, c, w) in s["c"].items()}
        self.set_parameters(*s["par"])


# ---------------------------------------------------------------------------------------
class PIController:
    """Discrete PI controller with output limits and anti-windup by conditional integration.

    e = direction * (setpoint - measurement); u = clamp(bias + kp e + I, u_min, u_max);
    I += ki e h only while the output is not saturated, or when e drives it back out of
    saturation (Astrom & Hagglund 2006, "PID Controllers", sec. 3.5, clamping). The output
    computed at the end of a step is held by the master over the next step (no direct
    feedthrough). ``direction`` = -1 for a reverse-acting loop such as tip speed -> x50
    (a higher speed makes the product finer).
    """

    def __init__(self, setpoint, kp, ki, u_min, u_max, bias, direction=-1.0):
        if not u_min < u_max:
            raise UnitInputError("u_min", u_min, f"must be below u_max = {u_max!r}")
        self.setpoint, self.kp, self.ki = float(setpoint), float(kp), float(ki)
        self.u_min, self.u_max, self.bias, self.direction = float(u_min), float(u_max), float(bias), float(direction)
        self.reset()

    def reset(self):
        self.t_s = 0.0
        self.integral = 0.0
        self.error = 0.0
        self.u = min(max(self.bias, self.u_min), self.u_max)
        self.saturated = 0.0

    def step(self, h, measurement):
        if not math.isfinite(measurement):
            raise UnitInputError("measurement", measurement, "must be finite")
        e = self.direction * (self.setpoint - measurement)
        v = self.bias + self.kp * e + self.integral
        sat_hi, sat_lo = v >= self.u_max, v <= self.u_min
        if not ((sat_hi and e > 0.0) or (sat_lo and e < 0.0)):
            self.integral += self.ki * e * h
        v = self.bias + self.kp * e + self.integral
        self.u = min(max(v, self.u_min), self.u_max)
        self.saturated = 1.0 if v != self.u else 0.0
        self.error = e
        self.t_s += h

    def outputs(self):
        return {"output": self.u, "error": self.error, "integral": self.integral, "saturated": self.saturated}

    def get_state(self):
        return {"t_s": self.t_s, "integral": self.integral, "error": self.error, "u": self.u,
                "saturated": self.saturated,
                "setpoint": self.setpoint}

    def set_state(self, s):
        for k in ("t_s", "integral", "error", "u", "saturated", "setpoint"):
            setattr(self, k, float(s[k]))
