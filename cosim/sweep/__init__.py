"""sweep: run one scenario once per combination of its ``sweep:`` values.

Owns the ``sweep:`` section and ``${...}`` placeholders (``spec``), running
the combinations in parallel processes each into its own folder, and the
sweep's tables (``visibility.csv``, ``manifest.csv``). It reuses ``sync.Run``
for every run and ``conspicuity`` for the measurements; it never touches a
run's own outputs.
"""

from cosim.sweep.spec import SweepSpec, parse_sweep, read_sweep, substitute

__all__ = ["SweepSpec", "parse_sweep", "read_sweep", "substitute"]
