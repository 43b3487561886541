"""sweep: run one scenario once per combination of its ``sweep:`` values.

Owns which combinations a sweep runs (``spec``: ``only:``, folder names),
running them in parallel processes each into its own folder, and the
sweep's tables (``visibility.csv``, ``manifest.csv``). The ``${...}``
placeholders are the scenario language's (``cosim.scenario.placeholders``).
It reuses ``sync.Run`` for every run and ``conspicuity`` for the
measurements; it never touches a run's own outputs.
"""
