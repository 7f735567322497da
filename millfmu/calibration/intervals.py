"""The fitted constants' uncertainty and what the residuals say: the error model, the
covariance of the constants' logarithms and their 95 % intervals, and the lack-of-fit
tests. Arrays in, numbers and words out: no model runs here.

- ``independent`` errors (and data with one value per time): Gauss-Newton s^2 (J^T J)^-1,
  s^2 = sum r^2 / (n - p), Student's t with n - p degrees of freedom (Bates & Watts 1988,
  ch. 2);
- ``per_sample`` errors (an error shared by all values of one sample, as a laser-diffraction
  measurement shifts a sample's whole distribution): a cluster-robust (sandwich)
  covariance with one cluster per measurement time, the CR2 small-sample correction (Bell &
  McCaffrey 2002; Pustejovsky & Tipton 2018) and Student's t with G - 1 degrees of freedom
  (G times);
- lack of fit: a trend of the per-time mean residual with time (Kendall's tau, exact) and,
  for x10/x50/x90, a size column off the others at every time (F test).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .measured import SIZE_COLUMNS, Data

#: Error models of :func:`millfmu.calibration.calibrate`: every value's error independent,
#: or an error shared by the values of one sample (one measurement time) on top of
#: independent ones.
ERROR_MODELS = ("independent", "per_sample")
#: Small-sample correction of the cluster-robust covariance: "CR2" (bias-reduced, Bell &
#: McCaffrey 2002) or "CR1" (G/(G-1) (n-1)/(n-p)); intervals use t with G - 1 dof either way.
CLUSTER_CORRECTION = "CR2"
#: Significance level of the lack-of-fit tests (each); with independent or per-sample noise
#: each fires in at most this share of fits.
LACK_OF_FIT_P = 0.01
#: Smallest systematic residual reported as lack of fit [residual unit: 1 % of a size, 0.01 of
#: Q3 or of a fraction]: below it a pattern is the model's curvature in its constants (the
#: tests are exact only for a linear model), far inside what a size analysis reproduces.
LACK_OF_FIT_MIN = 0.01


def error_model(data: Data, p: int, asked: str | None, notes: list) -> str:
    """The error model the intervals take: ``asked`` ("independent", "per_sample" or None:
    per_sample where some time has more than one quantity, else independent), falling back
    to independent errors where per-sample ones cannot be told (a note in ``notes`` says so)."""
    n_groups = len(data.times_s)
    # Some time has more than one quantity (x10/x50/x90, Q3 at several sizes): one sample's values, which may
    # share an error. Repeats of one quantity at one time are fitted as independent measurements (Data.notes).
    shared = len({(row[0], row[1], row[2]) for row in data.rows}) > n_groups
    model = "per_sample" if asked is None and shared else (asked or "independent").replace("-", "_")
    if model == "per_sample" and not shared:
        notes.append("per-sample errors asked for, but each time has one quantity: they are independent errors")
        model = "independent"
    if model == "per_sample" and n_groups <= p:
        notes.append(f"per-sample errors asked for, but {n_groups} time(s) cannot give an interval for {p} constant(s) "
                     f"with an error shared per time: intervals take every value's error as independent")
        model = "independent"
    return model


@dataclass
class Intervals:
    """The constants' uncertainty at the optimum, in ln(constant): covariance ``cov``,
    standard errors ``sd``, correlation ``corr`` (lists), the t quantile ``tq`` of 95 %
    intervals with ``dof`` degrees of freedom, how they were made (``method``) and the
    design's (J^T J)^-1 (``JtJinv``)."""

    cov: np.ndarray
    sd: np.ndarray
    corr: list
    tq: float
    dof: int
    method: str
    JtJinv: np.ndarray

    def design_correlation(self) -> float:
        """Whether the data tell a pair apart: the design's (J^T J)^-1 correlation (the
        cluster-robust estimate of it scatters from sample to sample with few times); 0
        for one constant."""
        if len(self.sd) != 2:
            return 0.0
        M = self.JtJinv
        return M[0, 1] / math.sqrt(M[0, 0] * M[1, 1])


def intervals(data: Data, J: np.ndarray, r: np.ndarray, model: str) -> Intervals:
    """The uncertainty of the constants' logarithms from the Jacobian ``J`` and residuals ``r``
    at the optimum under the error ``model``; needs more values than constants."""
    from scipy import stats

    n, p = J.shape
    JtJinv = np.linalg.inv(J.T @ J)
    if model == "per_sample":
        groups = np.array([data.times_s.index(row[0]) for row in data.rows])
        n_groups = len(data.times_s)
        cov = cluster_cov(J, r, groups, JtJinv, CLUSTER_CORRECTION)
        t_dof = n_groups - 1
        method = (f"cluster-robust (sandwich) covariance, one cluster per measurement time ({n_groups}), "
                  f"{CLUSTER_CORRECTION} small-sample correction, Student's t with {dof_words(t_dof)}")
    else:
        cov = float(r @ r) / (n - p) * JtJinv
        t_dof = n - p
        method = f"s^2 (J^T J)^-1 (independent errors), Student's t with {dof_words(t_dof)}"
    sd = np.sqrt(np.diag(cov))
    corr = (cov / np.outer(sd, sd)).tolist()
    return Intervals(cov, sd, corr, float(stats.t.ppf(0.975, t_dof)), t_dof, method, JtJinv)


def cluster_cov(J, r, groups, JtJinv, correction="CR2"):
    """Cluster-robust covariance (JtJ)^-1 (sum_g J_g^T u_g u_g^T J_g) (JtJ)^-1 of the
    constants' logarithms, clusters ``groups`` (one per measurement time). CR2: u_g =
    (I - H_gg)^(-1/2) r_g with the hat matrix H = J (J^T J)^-1 J^T (unbiased when the errors
    are in fact independent and equal); CR1: u_g = r_g, the sum times G/(G-1) (n-1)/(n-p)."""
    n, p = J.shape
    labels = np.unique(groups)
    meat = np.zeros((p, p))
    for g in labels:
        idx = np.flatnonzero(groups == g)
        Jg, rg = J[idx], r[idx]
        if correction == "CR2":
            Hgg = Jg @ JtJinv @ Jg.T
            w, V = np.linalg.eigh(np.eye(len(idx)) - Hgg)
            rg = V @ ((V.T @ rg) / np.sqrt(np.clip(w, 1e-12, None)))
        s = Jg.T @ rg
        meat += np.outer(s, s)
    if correction == "CR1":
        G = len(labels)
        meat *= G / (G - 1) * (n - 1) / max(n - p, 1)
    return JtJinv @ meat @ JtJinv


def lack_of_fit(data: Data, r, J) -> list:
    """What in the residuals ``r`` is systematic beyond the noise (independent or shared per
    time): a trend of the per-time mean residual with time (Kendall's tau, exact) and, for
    x10/x50/x90, a size column off the others at every time (F test of column terms in a
    regression of the residuals on each time's mean and the Jacobian ``J``, whose terms take up
    what the fitted constants' own error adds). Each test at level :data:`LACK_OF_FIT_P`."""
    r = np.asarray(r, dtype=float)
    out = []
    trend = _trend(data, r)
    if trend:
        out.append(trend)
    if data.kind == "sizes":
        columns = _column_offsets(data, r, J)
        if columns:
            out.append(columns)
    return out


def _trend(data: Data, r: np.ndarray) -> str | None:
    """The per-time mean residual's trend with time in words, where Kendall's tau finds one."""
    from scipy import stats

    times = data.times_s
    means = np.array([np.mean([ri for ri, row in zip(r, data.rows) if row[0] == t]) for t in times])
    if len(times) < 5:
        return None
    tau, pv = stats.kendalltau(times, means, method="exact")
    if not (np.isfinite(pv) and pv < LACK_OF_FIT_P and np.ptp(means) > 2 * LACK_OF_FIT_MIN):
        return None
    text = (f"residuals {'rise' if tau > 0 else 'fall'} with time: mean per time {means[0]:+.3g} at {times[0]:g} s, "
            f"{means[-1]:+.3g} at {times[-1]:g} s (Kendall's tau {tau:+.2f}, p = {pv:.2g})")
    if data.kind == "sizes":
        text += (f"; the model's sizes {'fall behind' if tau > 0 else 'run ahead of'} the data's as grinding "
                 f"goes on (its grinding kinetics has another shape)")
        signs = []
        for col in SIZE_COLUMNS:
            sg = "".join("+" if ri > 0 else "-" for ri, row in zip(r, data.rows) if row[1] == col)
            if sg:
                signs.append(f"{col.split('_')[0]} {sg}")
        text += "; signs by time: " + ", ".join(signs)
    return text


def _column_offsets(data: Data, r: np.ndarray, J) -> str | None:
    """x10/x50/x90 columns off each other at every time in words, where the F test finds them."""
    from scipy import stats

    times = data.times_s
    cols = [c for c in SIZE_COLUMNS if any(row[1] == c for row in data.rows)]
    table = {(row[0], row[1]): ri for ri, row in zip(r, data.rows)}
    full = [t for t in times if all((t, c) in table for c in cols)]
    if len(cols) < 2 or len(full) < 3:
        return None
    R = np.array([[table[(t, c)] for c in cols] for t in full])
    G, C = R.shape
    dev = R - R.mean(axis=1, keepdims=True)
    col_eff = dev.mean(axis=0)
    # F test of the columns in r ~ time + J (+ column): the fitted constants' own error (r = e - J dtheta)
    # moves the columns apart as the model's sensitivities differ by column; J's terms absorb that.
    where = {(row[0], row[1]): i for i, row in enumerate(data.rows)}
    idx = [where[(t, c)] for t in full for c in cols]
    X0 = np.hstack([np.kron(np.eye(G), np.ones((C, 1))), np.asarray(J, dtype=float)[idx]])
    X1 = np.hstack([X0, np.kron(np.ones((G, 1)), np.eye(C)[:, 1:])])
    y = r[idx]

    def rss(X):
        beta = np.linalg.lstsq(X, y, rcond=None)[0]
        return float(np.sum((y - X @ beta) ** 2)), int(np.linalg.matrix_rank(X))

    (rss0, k0), (rss1, k1) = rss(X0), rss(X1)
    dfn, dfe = k1 - k0, len(y) - k1
    if dfn < 1 or dfe < 1:
        return None
    F = ((rss0 - rss1) / dfn) / (rss1 / dfe) if rss1 > 1e-30 else math.inf
    pv = float(stats.f.sf(F, dfn, dfe)) if math.isfinite(F) else 0.0
    if not (pv < LACK_OF_FIT_P and np.max(np.abs(col_eff)) > LACK_OF_FIT_MIN):
        return None
    spread = col_eff[-1] - col_eff[0]
    offs = ", ".join(f"{c.split('_')[0]} {e:+.3g}" for c, e in zip(cols, col_eff))
    return (f"size columns lie off each other at every time: mean residual less each time's mean {offs} "
            f"(F = {F:.3g}, p = {pv:.2g}); the model's distribution is {'wider' if spread > 0 else 'narrower'} "
            f"than the data's ({cols[-1].split('_')[0]}/{cols[0].split('_')[0]} off by a factor "
            f"{math.exp(abs(spread)):.3g})")


def dof_words(n: int) -> str:
    """'1 degree of freedom', 'n degrees of freedom'."""
    return f"{n} degree{'s' if n != 1 else ''} of freedom"
