"""What every figure cosim draws shares: log axes read as plain numbers.

matplotlib labels a log axis that spans less than a decade with minor ticks
such as ``2x10^1, 3x10^1``; a reader wants ``20, 30``. ``plain_log_axis``
puts ticks at 1, 2 and 5 times each power of ten (every integer multiple
when the axis spans less than a decade) and writes them as ordinary numbers.
"""

from __future__ import annotations

from typing import Any


def plain_number(v: float) -> str:
    """``v`` as a reader writes it: 20, 0.5, 1500, 2e+06 for very large."""
    if v == 0:
        return "0"
    if abs(v) >= 1e6 or abs(v) < 1e-3:
        return f"{v:.0e}"
    return f"{v:,.6g}".replace(",", "\u2009") if abs(v) >= 1e4 else f"{v:.6g}"


def plain_log_axis(ax: Any, which: str = "x") -> None:
    """Log scale on ``which`` ("x", "y" or "both") of ``ax``, its ticks
    labelled as plain numbers (see the module docstring)."""
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter, NullLocator

    for name in ("x", "y") if which == "both" else (which,):
        axis = ax.xaxis if name == "x" else ax.yaxis
        (ax.set_xscale if name == "x" else ax.set_yscale)("log")
        lo, hi = sorted(ax.get_xlim() if name == "x" else ax.get_ylim())
        narrow = lo > 0 and hi / lo < 10
        subs = tuple(range(1, 10)) if narrow else (1.0, 2.0, 5.0)
        axis.set_major_locator(LogLocator(base=10, subs=subs))
        axis.set_major_formatter(FuncFormatter(lambda v, _pos: plain_number(v)))
        axis.set_minor_locator(NullLocator() if narrow else LogLocator(base=10,
                                                                       subs=tuple(range(1, 10))))
        axis.set_minor_formatter(NullFormatter())
