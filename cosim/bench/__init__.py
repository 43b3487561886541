"""bench: what ``cosim bench`` measures, with its baselines measured in the
same run: the pool against the serial loop and the no-communication ceiling
(``pool``), gymnasium's AsyncVectorEnv (``gym``), on the same fleet
(``fleet``), drawn by ``plot``. The benchmark scripts under ``benchmarks/``
use these too."""
