"""What every figure cosim draws shares: log axes read as plain numbers.

matplotlib labels a log axis with ``10^1``, ``2x10^1``; a reader wants
``10, 20``. ``plain_log_axis`` labels one axis with plain numbers: the
values drawn themselves when they are few and are what the axis counts (a
fleet size a point: 6, 12, 23, 32, 64, 128), else the 1-2-5 steps between
the smallest and the largest value and those two (3, 5, 10, 20, 50, 100,
200, 500; 1-3 steps over more than three decades, powers of ten over more
than five), labels nearer each other than 15 % of a decade thinned.
"""

from __future__ import annotations

from typing import Any

import numpy as np

#: a log axis with at most this many distinct values is labelled with them
MAX_VALUE_TICKS = 8


def plain_number(v: float) -> str:
    """``v`` as a reader writes it: 20, 0.5, 1500, 2e+06 (very large or small)."""
    if v == 0:
        return "0"
    if abs(v) >= 1e7 or abs(v) < 1e-3:
        return f"{v:.0e}"
    return f"{v:,.6g}" if abs(v) >= 1e4 else f"{v:.6g}"


def plain_log_axis(axis: Any, values: Any, own_values: bool = True) -> None:
    """Label the log ``axis`` (``ax.xaxis`` or ``ax.yaxis``, already on a log
    scale) with plain numbers for the data ``values`` along it (see the
    module docstring). ``own_values``: label the values themselves when
    there are few (counts such as fleet sizes); False: always the 1-2-5
    steps (measurements, whose own values are not round)."""
    from matplotlib.ticker import FixedLocator, NullFormatter, NullLocator

    v = np.unique(np.asarray([x for x in np.ravel(values) if x > 0], dtype=float))
    if not len(v):
        return
    lo, hi = float(v[0]), float(v[-1])
    decades = np.log10(hi / lo)
    if own_values and len(v) <= MAX_VALUE_TICKS and decades <= 3:
        ticks = [float(x) for x in v]
    else:  # 1-2-5 over up to 3 decades, 1-3 up to 5, the powers of ten beyond
        mantissas = (1, 2, 5) if decades <= 3 else (1, 3) if decades <= 5 else (1,)
        steps = [m * 10.0 ** e for e in range(int(np.floor(np.log10(lo))) - 1,
                                              int(np.ceil(np.log10(hi))) + 1) for m in mantissas]
        inside = {t for t in steps if lo <= t <= hi}
        ends = own_values and decades <= 3 or len(inside) < 2  # the range's own ends too
        ticks = sorted(inside | ({lo, hi} if ends else set()))
    keep = [ticks[0]]
    for t in ticks[1:]:
        if np.log10(t / keep[-1]) >= 0.065:
            keep.append(t)
        elif t == hi:  # the largest stays; the one before it goes
            keep[-1] = t
    axis.set_major_locator(FixedLocator(keep))
    axis.set_major_formatter(lambda x, _: plain_number(x))
    axis.set_minor_locator(NullLocator())
    axis.set_minor_formatter(NullFormatter())
