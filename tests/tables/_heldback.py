"""Held-back check of a shipped DEM table: every other node of one axis held back, the
table on the remaining nodes (twice the spacing, so a harder case than the full table)
interpolates it; the error is compared with the stated bound (interpolation error + 2 sigma,
sigma from the collision counts and the drift within each run, of the interpolating and of
the held-back node)."""

from __future__ import annotations

import numpy as np

from millfmu.dem import tables as T

#: (field, index into the field's value at one node); the zone index goes last
FIELDS = (("se_quantiles_norm", (0, None, 1)),  # median SE_tn
          ("collision_frequency_norm", (None,)),
          ("filling_local", (None,)))


def held_back(table, zones, min_filling: float, axes=None):
    """Error / bound of every held-back value in ``zones`` at fillings >= ``min_filling``,
    and the largest relative error per field: (ratios, worst). ``axes``: the axes whose
    every other node is held back (default all); an axis of 3 nodes keeps 2, where the
    lookup states no interpolation error, so its bounds are NaN."""
    ratios, worst = [], {}
    hs = table.node_sigma()
    names = list(table.axes)
    for a, name in enumerate(names):
        if axes is not None and name not in axes:
            continue
        keep = slice(None, None, 2)
        sl = tuple(keep if i == a else slice(None) for i in range(len(names)))
        kept = dict(table.axes)
        kept[name] = kept[name][keep]
        coarse = T.Table(axes=kept, zone_names=table.zone_names,
                         data={k: v[sl] for k, v in table.data.items()},
                         refs={k: v[sl] for k, v in table.refs.items()})
        for idx in np.ndindex(*table.shape):
            if idx[a] % 2 == 0 or table.axes["filling"][idx[names.index("filling")]] \
                    < min_filling - 1e-12:
                continue
            point = {n: float(table.axes[n][i]) for n, i in zip(names, idx)}
            lk = coarse.lookup(point)
            for k, sel in FIELDS:
                sel = tuple(zones if s is None else s for s in sel)
                want = table.data[k][idx][sel]
                err = np.abs(lk.values[k][sel] - want)
                bound = lk.error[k][sel] + 2.0 * np.hypot(lk.sigma[k][sel], hs[k][idx][sel])
                ratios.extend((err / bound).tolist())
                with np.errstate(divide="ignore", invalid="ignore"):
                    rel = err / want  # NaN where a zone holds no collisions
                if np.isfinite(rel).any():
                    worst[k] = max(worst.get(k, 0.0), float(np.nanmax(rel)))
    return np.array(ratios), worst
