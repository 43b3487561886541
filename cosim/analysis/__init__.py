"""analysis: measurements computed from a run's logged ground truth
(states.parquet, events.jsonl) and a model's own numbers. Reads files and
models; never runs a simulation."""
