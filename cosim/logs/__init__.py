"""logs: what a run leaves on disk, written so that a crash loses nothing
already written.

- ``states.parquet/``: a parquet dataset folder (the layout Spark and
  pyarrow write); each ``part-NNNNNN.parquet`` is complete and is renamed
  into place only once fully written, so every part on disk is readable
  after any crash. ``pyarrow.parquet.read_table(DIR/"states.parquet")`` and
  ``pandas.read_parquet`` read the folder as one table.
- ``events.jsonl``: one JSON object per line, flushed per event.
- ``summary.json``: written at the end of the run, whatever its end.

This package writes files; it never steps vehicles or decides when to stop.
"""

from cosim.logs.writers import (
    STATE_COLUMNS,
    EventLog,
    StateLog,
    read_states,
    write_json_atomic,
)

__all__ = ["STATE_COLUMNS", "EventLog", "StateLog", "read_states", "write_json_atomic"]
