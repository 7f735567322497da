"""Geometric particle-size grid and size distributions on it.

Classes are ordered by ascending size. Class ``i`` holds particles with sizes in
``(edges_m[i], edges_m[i+1]]``; the finest class also holds everything below
``edges_m[0]`` (fragments smaller than the grid's lower bound are kept, not lost).
Masses are in kg, sizes in m, Q3 is the cumulative mass fraction undersize [-].
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: Tolerance on the sum of the mass fractions of a size distribution given as input [-].
PSD_SUM_TOL = 1e-6


def checked_fractions(name: str, a, n: int, error, tol: float = PSD_SUM_TOL) -> np.ndarray:
    """Mass fractions [-] of ``n`` size classes given as input, scaled to sum to one.

    Raises ``error(name, value, allowed)`` (the caller's input-error class) for a wrong
    length, the first non-finite or negative entry (named ``name[i]``, 1-based) or a sum
    off one by more than ``tol``.
    """
    a = np.asarray(a, dtype=float)
    if a.shape != (n,):
        raise error(name, f"array of {a.size}", f"must have {n} entries (one per size class)")
    bad = np.flatnonzero(~np.isfinite(a) | (a < 0.0))
    if bad.size:
        raise error(f"{name}[{bad[0] + 1}]", float(a[bad[0]]), "must be finite and >= 0")
    tot = float(a.sum())
    if abs(tot - 1.0) > tol:
        raise error(name, f"sum {tot!r}", f"mass fractions must sum to 1 within {tol:g}")
    return a / tot


@dataclass(frozen=True)
class SizeGrid:
    """Geometric size grid.

    edges_m: class boundaries [m], ascending, length n + 1.
    """

    edges_m: np.ndarray

    @classmethod
    def geometric(cls, x_min_m: float, x_max_m: float, classes_per_octave: float) -> SizeGrid:
        """Grid from x_min_m upwards with ``classes_per_octave`` classes per doubling of size.

        The number of classes is ceil(classes_per_octave * log2(x_max/x_min)), so the top
        edge is at or just above x_max_m.
        """
        n = max(1, int(math.ceil(classes_per_octave * math.log2(x_max_m / x_min_m) - 1e-9)))
        ratio = 2.0 ** (1.0 / classes_per_octave)
        return cls(x_min_m * ratio ** np.arange(n + 1))

    @classmethod
    def with_classes(cls, x_min_m: float, x_max_m: float, n_classes: int) -> SizeGrid:
        """Grid with exactly ``n_classes`` geometric classes between x_min_m and x_max_m."""
        return cls(np.geomspace(x_min_m, x_max_m, n_classes + 1))

    @property
    def n(self) -> int:
        """Number of classes."""
        return len(self.edges_m) - 1

    @property
    def x_m(self) -> np.ndarray:
        """Representative size of each class [m]: geometric mean of its edges."""
        e = self.edges_m
        return np.sqrt(e[:-1] * e[1:])

    @property
    def ratio(self) -> float:
        """Ratio of neighbouring edges [-]."""
        return float(self.edges_m[1] / self.edges_m[0])


def outside_fractions(q3_at_edges: np.ndarray) -> tuple[float, float]:
    """Mass fractions [-] of a distribution below the lowest edge and above the top edge,
    from its Q3 at the grid's edges."""
    q = np.clip(np.asarray(q3_at_edges, dtype=float), 0.0, 1.0)
    return float(q[0]), float(1.0 - q.max())


def fractions_from_q3(grid: SizeGrid, q3_at_edges: np.ndarray) -> np.ndarray:
    """Class mass fractions from Q3 evaluated at the grid's edges.

    Mass below the lowest edge is put into the finest class and mass above the top edge
    into the coarsest, so the fractions always sum to one.
    """
    q = np.clip(np.asarray(q3_at_edges, dtype=float), 0.0, 1.0)
    q = np.maximum.accumulate(q)
    w = np.diff(q)
    w[0] += q[0]
    w[-1] += 1.0 - q[-1]
    w = np.maximum(w, 0.0)
    return w / w.sum()


def q3_lognormal(x_m: np.ndarray, x50_m: float, sigma_ln: float) -> np.ndarray:
    """Log-normal Q3 [-] with median x50_m [m] and standard deviation of ln x, sigma_ln [-]."""
    from scipy.special import ndtr

    return ndtr(np.log(np.asarray(x_m) / x50_m) / sigma_ln)


def q3_rrsb(x_m: np.ndarray, x63_m: float, n: float) -> np.ndarray:
    """Rosin-Rammler-Sperling-Bennett Q3 = 1 - exp(-(x/x63)^n) (DIN 66145)."""
    return -np.expm1(-((np.asarray(x_m) / x63_m) ** n))


def q3_table(x_m: np.ndarray, sizes_m: np.ndarray, q3: np.ndarray) -> np.ndarray:
    """Q3 from a table of sizes [m] and cumulative fractions [-], interpolated linearly in ln x.

    Below the first tabulated size Q3 is the first value (that mass sits in the finest
    class); above the last size it is one.
    """
    return np.interp(np.log(np.asarray(x_m)), np.log(sizes_m), q3, left=q3[0], right=1.0)


def characteristic_size_m(grid: SizeGrid, fractions: np.ndarray, q: float) -> float:
    """Size [m] at which Q3 reaches ``q`` (e.g. 0.5 for x50), interpolated in ln x.

    Q3 is taken as zero at the lowest edge and as the cumulative sum at each class's
    upper edge. Returns nan for an empty distribution.
    """
    total = float(np.sum(fractions))
    if not total > 0.0:
        return float("nan")
    cum = np.concatenate(([0.0], np.cumsum(fractions) / total))
    k = int(np.searchsorted(cum, q, side="left"))
    if k <= 0:
        return float(grid.edges_m[0])
    if k >= len(cum):
        return float(grid.edges_m[-1])
    c0, c1 = cum[k - 1], cum[k]
    le0, le1 = math.log(grid.edges_m[k - 1]), math.log(grid.edges_m[k])
    f = 0.0 if c1 <= c0 else (q - c0) / (c1 - c0)
    return float(math.exp(le0 + f * (le1 - le0)))


def characteristic_sizes_m(grid: SizeGrid, fractions: np.ndarray, qs, below: float = 0.0) -> tuple:
    """Sizes [m] at which Q3 reaches each of ``qs``; same rules as :func:`characteristic_size_m`,
    except that Q3 at the lowest edge is ``below``, the part of the finest class's fraction
    that lies below the grid: a size whose Q3 is within it is reported as the lowest edge."""
    return sizes_from_cumulative(np.log(grid.edges_m), np.asarray(fractions, dtype=float).cumsum(), qs, below)


def sizes_from_cumulative(log_edges, cum: np.ndarray, q, below: float = 0.0) -> tuple:
    """Sizes [m] at the Q3 levels ``q`` (a sequence) from the cumulative masses per class
    ``cum`` (any unit, cum[-1] the total), interpolated linearly in ln(x) within a class;
    ``log_edges`` the grid's ln(edges) (a sequence); ``below`` the part of the finest class
    below the grid (same unit as cum). A level is reached in the first class whose upper
    edge's Q3 reaches it. NaN for each level where the total is not positive."""
    return Q3Sizes(log_edges, q).sizes(cum, below)


class Q3Sizes:
    """:func:`sizes_from_cumulative` at fixed levels, call after call (the model's step):
    each level's class of the last call is tried first, two comparisons, since the sizes
    move little from one step to the next; a bisection only where the level left it. The
    same classes, hence the same sizes, as a bisection every time."""

    def __init__(self, log_edges, q):
        self.log_edges = [float(x) for x in log_edges]
        self.q = tuple(float(x) for x in q)
        self.k = [1] * len(self.q)  # last class (1-based) of each level

    def sizes(self, cum: np.ndarray, below: float = 0.0) -> tuple:
        """Sizes [m] at the levels for the cumulative masses ``cum`` (see
        :func:`sizes_from_cumulative`)."""
        total = cum.item(-1)
        if not total > 0.0:
            return tuple(math.nan for _ in self.q)
        n = cum.size
        le = self.log_edges
        exp = math.exp
        b = min(max(below, 0.0), cum.item(0))  # cumulative mass at the lowest edge
        out = []
        # Python floats (item): the same IEEE arithmetic as numpy's scalars, faster here
        for i, qi in enumerate(self.q):
            qt = qi * total
            if qt <= b:  # within the part below the grid: the lowest edge
                out.append(exp(le[0]))
                continue
            # class ki holds the level where its lower edge's Q3 is below it and its upper
            # edge's reaches it; then 0 < (qt - c0) / (c1 - c0) <= 1 needs no clamping
            ki = self.k[i]
            c0 = b if ki == 1 else cum.item(ki - 2)
            c1 = cum.item(ki - 1)
            if not c0 < qt <= c1:
                ki = min(int(cum.searchsorted(qt, side="left")) + 1, n)
                c0 = b if ki == 1 else cum.item(ki - 2)
                c1 = cum.item(ki - 1)
                self.k[i] = ki
            l0 = le[ki - 1]
            out.append(exp(l0 + (qt - c0) / (c1 - c0) * (le[ki] - l0)))
        return tuple(out)
