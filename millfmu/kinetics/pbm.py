"""Population balance of particle sizes by mass: operator, exact steps, adaptive steps.

Discrete breakage equation by mass (Austin et al. 1984; Reid 1965),

    dm_i/dt = -S_i m_i + sum_{j > i} b_ij S_j m_j,

on a geometric grid (classes ascending in size). The operator is assembled by averaging
over the parent sizes inside each class (Gauss-Legendre in ln y, mass uniform in ln y
within a class): for a parent of size y in class j the fragments in class i are
beta_i(y) = B(e_{i+1}/y) - B(e_i/y), and the part that stays in class j does not count as
leaving it. Diagonal entries are set to minus the sum of their column's off-diagonal
entries, so every column sums to zero to round-off: mass is conserved by construction.

Continuous operation: N equal, perfectly mixed tanks in series with dilution rate
D = Q / V_tank [1/s]; the mass that leaves the last tank is summed in an extra state (the
outflow accumulator), so the whole system matrix G is again column-conservative (see
:func:`system_matrix`). With rates and inputs frozen over a step h, the step is exact:

    y(t + h) = Phi y(t) + Gamma u,  [[Phi, Gamma], [0, I]] = expm([[G, F], [0, 0]] h)

(F maps the feed mass flow per class into the first tank). G is block lower-bidiagonal
with identical blocks, A - D I on the diagonal and D I below it; the two parts commute,
so Phi needs one exponential of a single tank's block (:class:`TanksInSeries`): the block
from tank j to tank j + k is p_k E, with E = expm(A h) and the Poisson weights
p_k = exp(-D h) (D h)^k / k!, and the outflow takes the Poisson tail. Gamma's blocks
Gamma_k = int_0^h p_k(s) expm(A s) ds follow from Gamma_0 (one exponential of twice a
tank's size) by the exact recursion Gamma_k (D I - A) = D Gamma_{k-1} - p_k(h) E (an
integration by parts), whose solve is non-expanding: D I - A is an M-matrix with column
sums D. The cost grows linearly with N (the dense exponential grows as N^3).
Phi and Gamma of such a (Metzler, conservative) G are non-negative with column sums 1 and
h; round-off is removed by clipping at zero and rescaling the columns to those sums, so
masses are never negative and mass balances close to round-off.
"""

from __future__ import annotations

from collections import OrderedDict

import numpy as np
from scipy.linalg import expm, lu_factor, lu_solve
from scipy.special import gammainc, gammaln

from .grid import SizeGrid


class BreakageOperator:
    """Geometry of the discrete breakage operator on a grid for a breakage function B(x/y).

    grid: the size grid; breakage_cdf: callable B(ratio) [-]; n_quad: Gauss-Legendre
    nodes per class; inert_fragments: if True (cells), broken mass goes to a second set of
    classes (debris) that is never stressed again. Fragments smaller than the grid's lower
    edge go to one more state, the below-grid mass, which is never stressed again either:
    a tank's state is [class 1..n, below grid] or, with inert fragments,
    [intact 1..n, debris 1..n, below grid] (:attr:`state_size` entries, below grid last).
    """

    def __init__(self, grid: SizeGrid, breakage_cdf, n_quad: int = 5, inert_fragments: bool = False):
        self.grid = grid
        self.inert_fragments = inert_fragments
        n = grid.n
        e = grid.edges_m
        t, w = np.polynomial.legendre.leggauss(n_quad)
        frac = 0.5 * (t + 1.0)  # nodes in (0, 1)
        le = np.log(e)
        #: Parent sizes where the selection function is evaluated, shape (n, n_quad) [m].
        self.nodes_m = np.exp(le[:-1, None] + frac[None, :] * (le[1:] - le[:-1])[:, None])
        #: Quadrature weights, summing to one over a class [-].
        self.weights = 0.5 * w
        # C[k, j, q] = B(e_k / y_jq) for the edges k = 0..n.
        c = np.asarray(breakage_cdf(e[:, None, None] / self.nodes_m[None, :, :]), dtype=float)
        c[e[:, None, None] >= self.nodes_m[None, :, :]] = 1.0
        # beta[i] for the classes i = 0..n-1, beta[n] below the grid's lower edge.
        beta = np.empty((n + 1, n, n_quad))
        beta[:n] = c[1:] - c[:-1]
        beta[n] = c[0]
        beta = np.maximum(beta, 0.0)
        # Normalise each parent's fragment distribution to exactly one.
        beta /= beta.sum(axis=0, keepdims=True)
        weighted = beta * self.weights[None, None, :]
        if not inert_fragments:
            # Only fragments in finer classes (or below the grid) leave class j; those inside j stay.
            keep = np.triu(np.ones((n + 1, n), bool), k=1)
            keep[n] = True
            weighted = weighted * keep[:, :, None]
        # Every broken cell leaves the intact class, into any debris class i <= j.
        self._w_frag = np.ascontiguousarray(weighted)
        m = self.state_size
        #: A permutation of a tank's states that makes :meth:`matrix` upper triangular (all
        #: transfers go to a lower index), for matrix exponentials that treat the diagonal
        #: exactly: below grid first, then the classes (debris, intact) from the top.
        self.upper_order = np.r_[m - 1, np.arange(m - 1)] if not inert_fragments else np.arange(m)[::-1].copy()

    @property
    def state_size(self) -> int:
        """Length of one tank's state vector (see the class docstring)."""
        return (2 * self.grid.n if self.inert_fragments else self.grid.n) + 1

    def matrix(self, s_nodes_per_s: np.ndarray) -> np.ndarray:
        """Breakage operator A [1/s] for selection rates at the quadrature nodes, shape (n, n_quad);
        every column sums to zero."""
        n = self.grid.n
        m = self.state_size
        s = np.asarray(s_nodes_per_s, dtype=float)
        flow = np.einsum("ijq,jq->ij", self._w_frag, s)  # (n + 1, n): into class i / below grid
        a = np.zeros((m, m))
        rows = np.r_[np.arange(n), m - 1] if not self.inert_fragments else np.r_[np.arange(n, 2 * n), m - 1]
        a[rows, :n] = flow
        # flow has a zero diagonal (fragments inside class j stay), so this is the column sum.
        a[np.arange(n), np.arange(n)] -= flow.sum(axis=0)
        return a

    def class_rates(self, s_nodes_per_s: np.ndarray) -> np.ndarray:
        """Class-averaged selection rate [1/s], mass uniform in ln x within a class."""
        return np.asarray(s_nodes_per_s) @ self.weights


def system_matrix(a: np.ndarray, n_tanks: int, dilution_per_s: float) -> np.ndarray:
    """Matrix G of N tanks in series with breakage operator a, plus the outflow accumulator.

    State layout: [outflow, tank N (m entries), ..., tank 1]; dilution_per_s = Q / V_tank.
    Block lower-bidiagonal in tank order, with identical blocks (see :class:`TanksInSeries`,
    which steps it without forming G). For a batch mill use n_tanks = 1, dilution_per_s = 0.
    """
    m = a.shape[0]
    size = n_tanks * m + 1
    g = np.zeros((size, size))
    eye = np.eye(m)
    for k in range(n_tanks):  # k = 0 is tank 1
        sl = tank_slice(k, m, n_tanks)
        g[sl, sl] = a - dilution_per_s * eye
        if k + 1 < n_tanks:
            g[tank_slice(k + 1, m, n_tanks), sl] = dilution_per_s * eye
        else:
            g[0, sl] = dilution_per_s
    return g


def tank_slice(k: int, m: int, n_tanks: int) -> slice:
    """Indices of tank k (0 = the first tank, which gets the feed) in the state vector."""
    start = 1 + (n_tanks - 1 - k) * m
    return slice(start, start + m)


def feed_matrix(m: int, n_tanks: int, n_in: int) -> np.ndarray:
    """Map of the feed mass flow per class [kg/s] (n_in classes) into the first tank's states."""
    f = np.zeros((n_tanks * m + 1, n_in))
    start = tank_slice(0, m, n_tanks).start
    f[start + np.arange(n_in), np.arange(n_in)] = 1.0
    return f


#: Masses [kg] and propagator entries below the smallest normal double (2.2e-308) are set to
#: zero: arithmetic on subnormal numbers is slow on x86 (a 101 x 101 matrix times a state with
#: 10 subnormal entries took 10.2 us instead of 2.3), and the default scene's coarse classes
#: decay into them within an hour of one-second steps (MillModel.step at 100 classes then
#: rose from 20 to 30 us), while such a value is below any round-off of a mass in the state.
SUBNORMAL = np.finfo(float).tiny


def flush_subnormal(a: np.ndarray) -> np.ndarray:
    """``a`` with its entries of magnitude below :data:`SUBNORMAL` set to zero, in place."""
    a[np.abs(a) < SUBNORMAL] = 0.0
    return a


def _flush_subnormal_nonnegative(a: np.ndarray) -> np.ndarray:
    """:func:`flush_subnormal` for an array without negative entries (a propagator's product
    with a state and a feed, all non-negative), in place: one comparison, no absolute
    value, a third less time at 100 classes."""
    a[a < SUBNORMAL] = 0.0
    return a


def _clean(p: np.ndarray, column_sum: float) -> np.ndarray:
    """Remove expm round-off: no negative entries, none below the smallest normal double
    (:data:`SUBNORMAL`), each column sums to column_sum."""
    p = flush_subnormal(np.maximum(p, 0.0))
    s = p.sum(axis=0)
    ok = s > 0.0
    p[:, ok] *= column_sum / s[ok]
    return p


def _expm_ordered(a: np.ndarray, order: np.ndarray | None) -> np.ndarray:
    """expm(a), computed on a[order][:, order] (upper triangular for the breakage operator's
    ``upper_order``) so that scipy's exact treatment of an upper triangular matrix's diagonal
    keeps stiff steps (rates x step ~ 1e12) accurate."""
    if order is None:
        return expm(a)
    ix = np.ix_(order, order)
    out = np.empty_like(a)
    out[ix] = expm(a[ix])
    return out


class TanksInSeries:
    """dy/dt = G y + F u for N equal tanks in series with breakage operator ``a`` [1/s] and
    dilution rate ``dilution_per_s`` = Q / V_tank [1/s], in the state layout of
    :func:`system_matrix` (outflow accumulator, tank N, ..., tank 1); F puts the feed mass
    flow per class [kg/s] of ``n_in`` classes into tank 1's first classes. A batch mill is
    N = 1, D = 0. Exact propagators over a step: :meth:`propagator` (see the module
    docstring for the method)."""

    def __init__(self, a: np.ndarray, n_tanks: int, dilution_per_s: float, n_in: int | None = None, order=None):
        self.a = np.asarray(a, dtype=float)
        self.order = order  # see _expm_ordered
        self.n_tanks = int(n_tanks)
        self.dilution_per_s = float(dilution_per_s)
        self.n_in = n_in

    @property
    def size(self) -> int:
        return self.n_tanks * self.a.shape[0] + 1

    def matrices(self):
        """The dense (G, F) (F None without feed): for checks against :func:`propagators`."""
        g = system_matrix(self.a, self.n_tanks, self.dilution_per_s)
        f = feed_matrix(self.a.shape[0], self.n_tanks, self.n_in) if self.n_in else None
        return g, f

    def propagator(self, h_s: float) -> SeriesPropagator:
        return SeriesPropagator(self, float(h_s))


class SeriesPropagator:
    """Exact step of :class:`TanksInSeries` over ``h_s`` seconds with frozen rates and feed.

    ``e`` = expm(A h) (m x m, columns summing to 1); ``p[k]`` the weight of the block k
    tanks downstream; ``tail[j]`` the fraction of tank j's content (j = 0 the first tank)
    that has left the last tank; ``gamma`` (N, m, n_in) the feed into each tank per unit
    feed mass flow and ``gamma_out`` (n_in) into the outflow [s].
    """

    def __init__(self, series: TanksInSeries, h_s: float):
        a, n, d = series.a, series.n_tanks, series.dilution_per_s
        m = a.shape[0]
        self.n_tanks, self.m = n, m
        self.e = _clean(_expm_ordered(a * h_s, series.order), 1.0)
        lam = d * h_s
        k = np.arange(n)
        # Poisson weights in logs: exp(-lam) underflows long before lam^k / k! overflows.
        with np.errstate(divide="ignore"):
            self.p = np.exp(-lam + k * np.log(lam) - gammaln(k + 1.0)) if lam > 0.0 else (k == 0).astype(float)
        # tail[j]: P(Poisson(lam) >= N - j), the regularized lower incomplete gamma function.
        self.tail = gammainc(n - k, lam) if lam > 0.0 else np.zeros(n)
        # Tank i receives p_{i-j} of tank j's content (j <= i): an upper Toeplitz matrix.
        self.toeplitz = np.zeros((n, n))
        for j in range(n):
            self.toeplitz[np.arange(n - j), np.arange(j, n)] = self.p[j]
        self.gamma = self.gamma_out = None
        if series.n_in:
            self.gamma, self.gamma_out = self._feed(a, n, d, h_s, series.n_in, series.order)
        #: every entry finite (extreme rates can make expm's overflow; a step refuses them)
        self.finite = bool(np.isfinite(self.e).all() and np.isfinite(self.p).all() and np.isfinite(self.tail).all()
                           and (self.gamma is None
                                or (np.isfinite(self.gamma).all() and np.isfinite(self.gamma_out).all())))
        if n == 1:
            # [[1, tail], [0, p0 e]] and [[gamma_out], [gamma_0]]: see apply
            self._whole = np.zeros((m + 1, m + 1))
            self._whole[0, 0] = 1.0
            self._whole[0, 1:] = self.tail[0]
            self._whole[1:, 1:] = self.p[0] * self.e
            self._whole_feed = None
            if self.gamma is not None:
                self._whole_feed = np.concatenate((self.gamma_out[None, :], self.gamma[0]))

    def _feed(self, a, n, d, h_s, n_in, order):
        m = a.shape[0]
        # Gamma_0 = int_0^h expm((A - D I) s) ds from the exponential of [[A - D I, I], [0, 0]] h
        # (Van Loan); triangular when A is, so stiff diagonals stay exact.
        aug = np.zeros((2 * m, 2 * m))
        aug[:m, :m] = a - d * np.eye(m)
        aug[:m, m:] = np.eye(m)
        g = np.empty((n, m, m))
        g[0] = _expm_ordered(aug * h_s, None if order is None else np.r_[order, m + order])[:m, m:]
        if n > 1 and d > 0.0:
            # Gamma_k (D I - A) = D Gamma_{k-1} - p_k E: transposed, one LU of (D I - A)^T.
            lu = lu_factor(d * np.eye(m) - a)
            for j in range(1, n):
                rhs = d * g[j - 1] - self.p[j] * self.e
                g[j] = lu_solve(lu, rhs.T, trans=1).T
        elif n > 1:
            g[1:] = 0.0  # no flow: nothing passes beyond the first tank
        g = g[:, :, :n_in]
        stacked = np.concatenate((np.zeros((1, n_in)), g.reshape(n * m, n_in)))
        # Column sums: h in all, the outflow takes what the tanks do not hold.
        stacked = np.maximum(stacked, 0.0)
        stacked[0] = np.maximum(h_s - stacked[1:].sum(axis=0), 0.0)
        stacked = _clean(stacked, h_s)
        return np.ascontiguousarray(stacked[1:].reshape(n, m, n_in)), stacked[0].copy()

    def apply(self, y: np.ndarray, u: np.ndarray | None = None) -> np.ndarray:
        """The state after the step from state ``y`` with feed ``u`` [kg/s per class]."""
        n, m = self.n_tanks, self.m
        if n == 1:
            # One tank (every batch mill): one product with the step's whole matrix, outflow
            # row included, instead of the block layout's reshapes and sums, which cost more
            # than the product itself at 100 classes.
            # ndarray.dot: the same BLAS product as @, with less call overhead per step
            y_new = self._whole.dot(y)
            if u is not None and self._whole_feed is not None:
                y_new += self._whole_feed.dot(u)
            return _flush_subnormal_nonnegative(y_new)
        tanks = y[1:].reshape(n, m)[::-1]  # tank 1 first
        mixed = tanks.T @ self.toeplitz if n > 1 or self.p[0] != 1.0 else tanks.T
        new = self.e @ mixed  # (m, N), column i = tank i + 1
        out = y[0] + float(self.tail @ tanks.sum(axis=1))
        if u is not None and self.gamma is not None:
            new += np.einsum("kmi,i->mk", self.gamma, u)
            out += float(self.gamma_out @ u)
        y_new = np.empty_like(y)
        y_new[0] = out
        y_new[1:] = new.T[::-1].ravel()
        return _flush_subnormal_nonnegative(y_new)


def propagators(g: np.ndarray, f: np.ndarray | None, h_s: float):
    """Exact propagators (Phi, Gamma) of dy/dt = G y + F u over h_s seconds.

    Gamma is None when f is None. Phi >= 0 with unit column sums, Gamma >= 0 with column sums
    h_s, up to round-off (made exact by rescaling; valid for column-conservative Metzler G).
    """
    size = g.shape[0]
    if f is None:
        return _clean(expm(g * h_s), 1.0), None
    k = f.shape[1]
    aug = np.zeros((size + k, size + k))
    aug[:size, :size] = g
    aug[:size, size:] = f
    e = expm(aug * h_s)
    return _clean(e[:size, :size], 1.0), _clean(e[:size, size:], h_s)


class LRUCache:
    """Least-recently-used cache: ``get(key, build)`` returns the cached value or builds it.

    Used for the exact propagators (keyed by rate set and step size) and the per-operating-
    point operators and numbers, so that repeated steps rebuild nothing.
    """

    def __init__(self, maxsize: int = 32):
        self.maxsize = maxsize
        self._d: OrderedDict = OrderedDict()

    def get(self, key, build):
        d = self._d
        try:
            v = d[key]
        except KeyError:
            v = d[key] = build()
            if len(d) > self.maxsize:
                d.popitem(last=False)
            return v
        d.move_to_end(key)
        return v


def adaptive_exponential_step(y0, t0_s, h_s, system, rtol=1e-6, atol=1e-12, h_min_s=None, max_substeps=100000):
    """Advance dy/dt = G(t, y) y + F u(t, y) over h_s with rates that change within the step.

    system(t, y) -> (TanksInSeries, u) gives the frozen system at time t and state y (u the
    feed [kg/s per class], or None). Exponential
    midpoint rule (second order): the midpoint state comes from a half step with the rates
    at the start, the full step uses the rates at the midpoint. Each substep is exact for
    its frozen system, so masses stay non-negative and conserved; the substep size is
    controlled by step doubling with the local error below rtol |y| + atol.
    Returns (y, number of accepted substeps).
    """

    def one(y, t, dt):
        series, u = system(t, y)
        y_half = series.propagator(0.5 * dt).apply(y, u)
        series, u = system(t + 0.5 * dt, y_half)
        return series.propagator(dt).apply(y, u)

    y = np.array(y0, dtype=float)
    t, t_end = t0_s, t0_s + h_s
    dt = h_s
    h_min = h_min_s if h_min_s is not None else h_s * 1e-12
    n_acc = 0
    for _ in range(max_substeps):
        if t >= t_end - 1e-15 * max(1.0, abs(t_end)):
            return y, n_acc
        dt = min(dt, t_end - t)
        full = one(y, t, dt)
        half = one(one(y, t, 0.5 * dt), t + 0.5 * dt, 0.5 * dt)
        err = np.max(np.abs(half - full) / (rtol * np.abs(half) + atol)) / 3.0
        if err <= 1.0 or dt <= h_min:
            # Richardson extrapolation would be third order but may go negative; keep
            # the two half steps, which are positive by construction.
            y = half
            t += dt
            n_acc += 1
            dt *= min(4.0, 0.9 * max(err, 1e-10) ** (-1.0 / 3.0))
        else:
            dt *= max(0.2, 0.9 * err ** (-1.0 / 3.0))
    raise RuntimeError(f"adaptive step did not reach t = {t_end} s in {max_substeps} substeps")
