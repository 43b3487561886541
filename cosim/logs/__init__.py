"""logs: what a run leaves on disk, written so that a crash loses nothing
already written.

- ``states.parquet/``: a parquet dataset folder (the layout Spark and
  pyarrow write); each ``part-NNNNNN.parquet`` is complete and is renamed
  into place only once fully written, so every part on disk is readable
  after any crash. ``pyarrow.parquet.read_table(DIR/"states.parquet")`` and
  ``pandas.read_parquet`` read the folder as one table. The ticks logged
  since the last part are journalled, one Arrow IPC record batch per tick,
  in ``_journal-NNNNNN.arrows`` (deleted once their part is written):
  ``read_states`` reads parts and journals, so a driver killed mid-run
  loses at most the tick it was writing.
- ``events.jsonl``: one JSON object per line, flushed per event.
- ``summary.json``: written at the end of the run, whatever its end.
- ``faulthandler.log``: Python tracebacks of a driver that crashed hard
  (segfault, abort); removed when empty.

This package writes those files, and reads them back as untrusted input
(``runfolder``: bounded, inside the folder, checked); it never steps
vehicles or decides when to stop.
"""

from cosim.logs.runfolder import RunFolder, read_states
from cosim.logs.writers import (
    RUN_OUTPUTS,
    STATE_COLUMNS,
    DiskReserve,
    EventLog,
    StateLog,
    clear_outputs,
    replacing,
    write_json_atomic,
)

__all__ = ["RUN_OUTPUTS", "STATE_COLUMNS", "DiskReserve", "EventLog", "RunFolder", "StateLog",
           "clear_outputs", "read_states", "replacing", "write_json_atomic"]
