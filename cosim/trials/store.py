"""Sessions and responses of conspicuity trials, in a database.

Owns the tables below and their CSV export. An embedded SQLite file by default
(``Store("trials.sqlite")``); any SQLAlchemy database URL otherwise
(``Store("postgresql+psycopg://...")``, the driver installed separately).

- ``sessions``: one row per participant session: the pseudonymous participant
  id, the display profile (screen size in pixels and millimetres, viewing
  distance), the trial order with the method, seed and session number it was
  drawn with, its state (``ready``, ``running``, ``paused``, ``finished``)
  and when it was created.
- ``live_reports``: one row per click on a feed of a live-console trial
  (its feed, the frame drawn there, the pixel in the frame's own
  coordinates, the page's click and draw times); ``(session, trial_index,
  report_key)`` is unique, the key the page's own for each click.
- ``live_commands``: one row per command the participant sent an aircraft
  from a live trial's map (the action, the vehicle, the point, the page's
  time, the server's, the run's sequence number and, once the run applied
  it, its tick and simulated time); ``(session, trial_index, seq)`` is
  unique.
- ``responses``: one row per response. ``(session, trial_index, kind)`` is
  unique: posting the same response again (a reload, a retry) returns the
  stored row and adds nothing, so a response is never duplicated, and the
  first one posted wins.
- ``instrument_answers``: one row per NASA-TLX block or SAGAT probe of a
  session (``instruments``, ``sagat``): the answer as checked (JSON), the
  raw and weighted TLX, a probe's scores per question (JSON; empty until
  scored) and its count of correct answers. ``(session, instrument,
  trial_index, item)`` is unique: the first answer posted wins.

``export_csv(db, path)`` writes ``EXPORT_COLUMNS`` in that order (the
analysis reads them): booleans as 0/1, a missing value as an empty field.
Nothing here knows about HTTP or the study file.
"""

from __future__ import annotations

import json
import math
import secrets
import stat
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, TextIO

import sqlalchemy as sa
from sqlalchemy.exc import IntegrityError

from cosim.errors import ConfigError
from cosim.trials.files import file_kind

EXPORT_COLUMNS = ("session", "participant", "trial_index", "practice", "protocol", "clip", "run",
                  "condition_speed_kt", "condition_alt_agl_m", "condition_target", "frame",
                  "video_time_s", "reaction_time_ms", "key", "target_in_view",
                  "eccentricity_deg", "onscreen_distance_mm", "target_angular_size_deg",
                  "camera_gap_deg", "target_depth_m", "viewing_distance_mm", "screen_width_mm",
                  "screen_height_mm", "screen_width_px", "screen_height_px", "recognised",
                  "reshown")
STATES = ("ready", "running", "paused", "finished")

metadata = sa.MetaData()
sessions = sa.Table(
    "sessions", metadata,
    sa.Column("id", sa.String(32), primary_key=True),
    sa.Column("participant", sa.String(64), nullable=False),
    sa.Column("study", sa.String(200), nullable=False),
    sa.Column("protocol", sa.String(16), nullable=False),
    sa.Column("screen_width_px", sa.Integer, nullable=False),
    sa.Column("screen_height_px", sa.Integer, nullable=False),
    sa.Column("screen_width_mm", sa.Float, nullable=False),
    sa.Column("screen_height_mm", sa.Float, nullable=False),
    sa.Column("viewing_distance_mm", sa.Float, nullable=False),
    sa.Column("order_method", sa.String(16), nullable=False),
    sa.Column("seed", sa.BigInteger, nullable=False),
    sa.Column("session_number", sa.Integer, nullable=False),
    sa.Column("trial_order", sa.Text, nullable=False),  # JSON: [{index, practice, clip, ...}]
    sa.Column("state", sa.String(16), nullable=False),
    sa.Column("created", sa.String(32), nullable=False),  # ISO 8601, UTC
    # the size (device px) the participant's page last reported
    sa.Column("window_width_px", sa.Integer),
    sa.Column("window_height_px", sa.Integer),
)
#: the answers to a study's instruments (``instruments``, ``sagat``): one row a
#: NASA-TLX block or a SAGAT probe of a session's trial
instrument_answers = sa.Table(
    "instrument_answers", metadata,
    sa.Column("id", sa.Integer, primary_key=True, autoincrement=True),
    sa.Column("session", sa.String(32), sa.ForeignKey("sessions.id"), nullable=False),
    sa.Column("participant", sa.String(64), nullable=False),
    sa.Column("instrument", sa.String(16), nullable=False),  # "tlx" or "sagat"
    sa.Column("trial_index", sa.Integer, nullable=False),  # tlx: the block's last trial
    sa.Column("item", sa.Integer, nullable=False),  # tlx: the block; sagat: the probe
    sa.Column("answer", sa.Text, nullable=False),  # JSON, as checked
    sa.Column("raw_tlx", sa.Float),
    sa.Column("weighted_tlx", sa.Float),  # null: the study asks no weights
    # sagat: JSON {question id: {correct, error, truth}}; null until scored
    sa.Column("scores", sa.Text),
    sa.Column("correct", sa.Integer),  # sagat: the questions answered correctly
    sa.Column("questions", sa.Integer),  # sagat: the questions scored
    sa.Column("created", sa.String(32), nullable=False),
    sa.UniqueConstraint("session", "instrument", "trial_index", "item",
                        name="one_answer_per_item"),
)
responses = sa.Table(
    "responses", metadata,
    sa.Column("id", sa.Integer, primary_key=True, autoincrement=True),
    sa.Column("session", sa.String(32), sa.ForeignKey("sessions.id"), nullable=False),
    sa.Column("participant", sa.String(64), nullable=False),
    sa.Column("trial_index", sa.Integer, nullable=False),
    sa.Column("kind", sa.String(16), nullable=False),
    sa.Column("practice", sa.Boolean, nullable=False),
    sa.Column("protocol", sa.String(16), nullable=False),
    sa.Column("clip", sa.String(400), nullable=False),
    sa.Column("run", sa.String(200), nullable=False),
    sa.Column("conditions", sa.Text, nullable=False),  # JSON {name: value} (all of them)
    sa.Column("condition_speed_kt", sa.String(64)),
    sa.Column("condition_alt_agl_m", sa.String(64)),
    sa.Column("condition_target", sa.String(64)),
    sa.Column("key", sa.String(32), nullable=False),
    sa.Column("frame", sa.Integer),
    sa.Column("video_time_s", sa.Float),
    sa.Column("reaction_time_ms", sa.Float),
    sa.Column("target_in_view", sa.Boolean),
    sa.Column("eccentricity_deg", sa.Float),
    sa.Column("onscreen_distance_mm", sa.Float),
    sa.Column("target_angular_size_deg", sa.Float),
    sa.Column("camera_gap_deg", sa.Float),  # see cosim.trials.measures
    sa.Column("target_depth_m", sa.Float),  # the target centre along the optical axis
    sa.Column("viewing_distance_mm", sa.Float, nullable=False),
    sa.Column("screen_width_mm", sa.Float, nullable=False),
    sa.Column("screen_height_mm", sa.Float, nullable=False),
    sa.Column("screen_width_px", sa.Integer, nullable=False),
    sa.Column("screen_height_px", sa.Integer, nullable=False),
    sa.Column("recognised", sa.Boolean),
    # the trial had been shown before (the page was reloaded while it played)
    sa.Column("reshown", sa.Boolean),
    sa.Column("created", sa.String(32), nullable=False),
    sa.UniqueConstraint("session", "trial_index", "kind", name="one_response_per_trial"),
)
_RESPONSE_FIELDS = tuple(c.name for c in responses.columns if c.name not in ("id", "created"))
_INSTRUMENT_FIELDS = tuple(c.name for c in instrument_answers.columns
                           if c.name not in ("id", "created"))
#: a live-console trial's reports: one row per click on a feed (``live_routes``)
live_reports = sa.Table(
    "live_reports", metadata,
    sa.Column("id", sa.Integer, primary_key=True, autoincrement=True),
    sa.Column("session", sa.String(32), sa.ForeignKey("sessions.id"), nullable=False),
    sa.Column("participant", sa.String(64), nullable=False),
    sa.Column("trial_index", sa.Integer, nullable=False),
    sa.Column("condition", sa.String(200), nullable=False),
    # the page's own id of the click: a report posted again (a retry) is kept once
    sa.Column("report_key", sa.String(64), nullable=False),
    sa.Column("feed", sa.Integer, nullable=False),  # the condition's feed number
    sa.Column("feed_name", sa.String(200), nullable=False),  # VEHICLE/CAMERA
    sa.Column("frame", sa.Integer, nullable=False),  # the feed's frame drawn at the click
    sa.Column("x_px", sa.Float, nullable=False),  # in the frame's own pixels
    sa.Column("y_px", sa.Float, nullable=False),
    # the page's clock (performance.now(), ms): the click and when that frame was drawn
    sa.Column("click_time_ms", sa.Float, nullable=False),
    sa.Column("drawn_time_ms", sa.Float),
    sa.Column("run", sa.String(400), nullable=False),  # the trial's run folder
    sa.Column("created", sa.String(32), nullable=False),
    sa.UniqueConstraint("session", "trial_index", "report_key", name="one_row_per_report"),
)
_LIVE_FIELDS = tuple(c.name for c in live_reports.columns if c.name not in ("id", "created"))
#: the columns of ``cosim trials export --live``: every stored click, as stored
LIVE_EXPORT_COLUMNS = tuple(c.name for c in live_reports.columns if c.name != "id")
#: the commands a live trial's participant sent from the map (``live_routes``)
live_commands = sa.Table(
    "live_commands", metadata,
    sa.Column("id", sa.Integer, primary_key=True, autoincrement=True),
    sa.Column("session", sa.String(32), sa.ForeignKey("sessions.id"), nullable=False),
    sa.Column("participant", sa.String(64), nullable=False),
    sa.Column("trial_index", sa.Integer, nullable=False),
    sa.Column("condition", sa.String(200), nullable=False),
    sa.Column("seq", sa.Integer, nullable=False),  # the run's number of the command: 0, 1, ...
    sa.Column("vehicle", sa.String(64), nullable=False),
    sa.Column("action", sa.String(16), nullable=False),  # go, orbit or look
    sa.Column("north_m", sa.Float, nullable=False),  # the point, in the scenario's frame
    sa.Column("east_m", sa.Float, nullable=False),
    sa.Column("client_time_ms", sa.Float),  # the page's clock (performance.now()) at the click
    sa.Column("server_time", sa.String(32), nullable=False),  # received (ISO 8601, UTC)
    sa.Column("tick", sa.Integer),  # the run's tick it was applied at (null until then)
    sa.Column("sim_time_s", sa.Float),
    sa.Column("run", sa.String(400), nullable=False),  # the trial's run folder
    sa.UniqueConstraint("session", "trial_index", "seq", name="one_row_per_command"),
)
_COMMAND_FIELDS = tuple(c.name for c in live_commands.columns if c.name != "id")
#: the columns of ``cosim trials export --live-commands``: every stored command
LIVE_COMMAND_COLUMNS = _COMMAND_FIELDS


def _session_id() -> str:
    """A new session's id: 12 URL-safe random characters beginning with a letter or a
    digit, so that an exported id never reads as an option on a command line or is
    escaped as a would-be formula in a spreadsheet (a cell beginning with "-")."""
    while True:
        sid = secrets.token_urlsafe(9)
        if sid[0].isalnum():
            return sid


def _now() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="milliseconds")


def shown_url(db: str) -> str:
    """A database URL fit for logs and messages: its password hidden."""
    if "://" not in db:
        return db
    try:
        return str(sa.engine.make_url(db).render_as_string(hide_password=True))
    except Exception:  # noqa: BLE001 - not a URL SQLAlchemy reads: say only its scheme
        return db.split("://", 1)[0] + "://..."


def database_url(db: str | Path) -> str:
    """A SQLAlchemy URL: ``db`` itself if it has a scheme, else a SQLite file path."""
    s = str(db)
    if "://" in s:
        return s
    return f"sqlite:///{Path(s).expanduser().resolve()}"


class Store:
    """The trial database (a context manager; ``close`` may be called twice)."""

    def __init__(self, db: str | Path) -> None:
        url = database_url(db)
        _check_sqlite_file(url, db)
        try:
            self.engine = sa.create_engine(url)
            if self.engine.dialect.name == "sqlite":
                sa.event.listen(self.engine, "connect", _sqlite_pragmas)
            metadata.create_all(self.engine)
            _add_missing_columns(self.engine)
        except Exception as e:  # noqa: BLE001 - a bad URL, a missing driver, a locked file
            raise ConfigError(f"cannot open the trial database {shown_url(str(db))}: {e}"
                              ) from None

    def __enter__(self) -> Store:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        self.engine.dispose()

    # --- sessions ---
    def session_count(self, study: str) -> int:
        with self.engine.connect() as c:
            return int(c.execute(sa.select(sa.func.count()).select_from(sessions)
                                 .where(sessions.c.study == study)).scalar_one())

    def create_session(self, *, participant: str, study: str, protocol: str,
                       display: dict[str, Any], order_method: str, seed: int,
                       session_number: int, trial_order: list[dict[str, Any]]) -> dict[str, Any]:
        row = {"id": _session_id(), "participant": participant, "study": study,
               "protocol": protocol, **display, "order_method": order_method, "seed": seed,
               "session_number": session_number, "trial_order": json.dumps(trial_order),
               "state": "ready", "created": _now()}
        with self.engine.begin() as c:
            c.execute(sessions.insert().values(**row))
        return self.session(row["id"]) or row

    def session(self, session_id: str) -> dict[str, Any] | None:
        with self.engine.connect() as c:
            r = c.execute(sessions.select().where(sessions.c.id == session_id)).mappings().first()
        if r is None:
            return None
        out = dict(r)
        out["trial_order"] = json.loads(out["trial_order"])
        return out

    def sessions(self) -> list[dict[str, Any]]:
        """Every session (newest first) with ``answered``: its trials with a response."""
        counts = (sa.select(responses.c.session, sa.func.count().label("n"))
                  .group_by(responses.c.session).subquery())
        q = (sa.select(sessions, sa.func.coalesce(counts.c.n, 0).label("answered"))
             .select_from(sessions.outerjoin(counts, counts.c.session == sessions.c.id))
             .order_by(sessions.c.created.desc()))
        with self.engine.connect() as c:
            rows = [dict(r) for r in c.execute(q).mappings()]
        for r in rows:
            r["trials"] = len(json.loads(r.pop("trial_order")))
        return rows

    def set_window(self, session_id: str, width_px: int, height_px: int) -> None:
        """Record the size (device px) the session's participant page reports."""
        with self.engine.begin() as c:
            c.execute(sessions.update().where(sessions.c.id == session_id)
                      .values(window_width_px=width_px, window_height_px=height_px))

    def set_state(self, session_id: str, state: str) -> None:
        if state not in STATES:
            raise ValueError(f"state must be one of {', '.join(STATES)}, got {state!r}")
        with self.engine.begin() as c:
            c.execute(sessions.update().where(sessions.c.id == session_id).values(state=state))

    # --- instruments ---
    def record_instrument(self, row: dict[str, Any]) -> tuple[dict[str, Any], bool]:
        """Store one instrument answer (``instrument_answers``' columns;
        ``answer`` and ``scores`` as JSON-able values); (the stored row, True)
        or, when this session's item already has one, (that row, False): the
        first answer posted wins."""
        values = {**row, "answer": json.dumps(row["answer"]),
                  "scores": None if row.get("scores") is None else json.dumps(row["scores"])}
        stored, created = self._insert_once(
            instrument_answers, _INSTRUMENT_FIELDS, values, ("instrument", "item"),
            f"{row.get('instrument')} answer {row.get('item')} of")
        return _instrument_row(stored), created

    def instrument_answers(self, session_id: str | None = None,
                           instrument: str | None = None) -> list[dict[str, Any]]:
        """Instrument answers (``answer`` and ``scores`` decoded), in the order
        stored; of one session and one instrument if given."""
        q = instrument_answers.select().order_by(instrument_answers.c.id)
        if session_id is not None:
            q = q.where(instrument_answers.c.session == session_id)
        if instrument is not None:
            q = q.where(instrument_answers.c.instrument == instrument)
        with self.engine.connect() as c:
            return [_instrument_row(r) for r in c.execute(q).mappings()]

    def score_instrument(self, answer_id: int, scores: dict[str, Any]) -> None:
        """Keep a SAGAT answer's scores (``{question id: {correct, ...}}``),
        counted into ``correct`` and ``questions``."""
        with self.engine.begin() as c:
            c.execute(instrument_answers.update().where(instrument_answers.c.id == answer_id)
                      .values(scores=json.dumps(scores), questions=len(scores),
                              correct=sum(bool(s["correct"]) for s in scores.values())))

    # --- responses ---
    def record_response(self, row: dict[str, Any]) -> tuple[dict[str, Any], bool]:
        """Store one response; (the stored row, True) or, when this session's
        trial already has a response of this kind, (that row, False)."""
        return self._insert_once(responses, _RESPONSE_FIELDS, row, ("kind",), "response to")

    def _insert_once(self, table: sa.Table, fields: tuple[str, ...], row: dict[str, Any],
                     keys: tuple[str, ...], what: str) -> tuple[dict[str, Any], bool]:
        """Insert ``row`` unless the row of its session, trial and ``keys`` is
        there: (the stored row, whether it was inserted now)."""
        values = {k: row.get(k) for k in fields}
        values["created"] = _now()
        try:
            with self.engine.begin() as c:
                c.execute(table.insert().values(**values))
            created = True
        except IntegrityError:
            created = False
        q = table.select().where(table.c.session == row["session"],
                                 table.c.trial_index == row["trial_index"],
                                 *(table.c[k] == row[k] for k in keys))
        with self.engine.connect() as c:
            stored = c.execute(q).mappings().first()
        if stored is None:  # the IntegrityError was something else (e.g. no such session)
            raise ConfigError(f"{what} trial {row.get('trial_index')} of session "
                              f"{row.get('session')} was refused by the database")
        return dict(stored), created

    def record_live_report(self, row: dict[str, Any]) -> tuple[dict[str, Any], bool]:
        """Store one click of a live trial; (the stored row, True) or, when
        the page posted this report before, (that row, False)."""
        return self._insert_once(live_reports, _LIVE_FIELDS, row, ("report_key",),
                                 "report of")

    def live_reports(self, session_id: str | None = None) -> list[dict[str, Any]]:
        """A session's live reports (None: every session's), in the order they
        were stored."""
        q = live_reports.select().order_by(live_reports.c.id)
        if session_id is not None:
            q = q.where(live_reports.c.session == session_id)
        with self.engine.connect() as c:
            return [dict(r) for r in c.execute(q).mappings()]

    def record_live_command(self, row: dict[str, Any]) -> dict[str, Any]:
        """Store one map command of a live trial (``live_commands``' columns;
        ``server_time`` now unless given); the stored row."""
        values = {k: row.get(k) for k in _COMMAND_FIELDS}
        values["server_time"] = row.get("server_time") or _now()
        with self.engine.begin() as c:
            c.execute(live_commands.insert().values(**values))
        return values

    def live_command_applied(self, session_id: str, trial_index: int, seq: int, tick: int,
                             sim_time_s: float) -> None:
        """Keep the tick and simulated time a stored command was applied at."""
        with self.engine.begin() as c:
            c.execute(live_commands.update().where(
                live_commands.c.session == session_id,
                live_commands.c.trial_index == trial_index, live_commands.c.seq == seq)
                .values(tick=tick, sim_time_s=sim_time_s))

    def live_commands(self, session_id: str | None = None) -> list[dict[str, Any]]:
        """A session's map commands (None: every session's), in the order stored."""
        q = live_commands.select().order_by(live_commands.c.id)
        if session_id is not None:
            q = q.where(live_commands.c.session == session_id)
        with self.engine.connect() as c:
            return [dict(r) for r in c.execute(q).mappings()]

    def responses(self, session_id: str | None = None) -> list[dict[str, Any]]:
        q = (sa.select(responses).select_from(responses.join(sessions))
             .order_by(sessions.c.created, responses.c.session, responses.c.trial_index,
                       responses.c.kind))
        if session_id is not None:
            q = q.where(responses.c.session == session_id)
        with self.engine.connect() as c:
            return [dict(r) for r in c.execute(q).mappings()]


def _instrument_row(r: Any) -> dict[str, Any]:
    out = dict(r)
    out["answer"] = json.loads(out["answer"])
    out["scores"] = None if out["scores"] is None else json.loads(out["scores"])
    return out


def _check_sqlite_file(url: str, db: str | Path) -> None:
    """A SQLite database that exists must be a regular file (a FIFO or a
    device would be waited on, or read as garbage): ``ConfigError`` if not."""
    try:
        u = sa.engine.make_url(url)
    except Exception:  # noqa: BLE001 - not a URL: Store says so when it opens it
        return
    if u.get_backend_name() != "sqlite" or u.database in (None, "", ":memory:"):
        return
    try:
        mode = Path(u.database).stat().st_mode
    except OSError:  # none yet: SQLite makes it
        return
    if not stat.S_ISREG(mode):
        raise ConfigError(f"cannot open the trial database {shown_url(str(db))}: it is "
                          f"{file_kind(mode)}, not a regular file")


def _add_missing_columns(engine: sa.Engine) -> None:
    """Bring a database made by an older cosim up to date: the nullable
    columns it lacks are added (empty for its rows); nothing is dropped."""
    have = sa.inspect(engine)
    prep = engine.dialect.identifier_preparer
    for table in metadata.sorted_tables:
        present = {c["name"] for c in have.get_columns(table.name)}
        for column in table.columns:
            if column.name in present:
                continue
            if not column.nullable:
                raise ConfigError(f"the {table.name} table lacks column {column.name!r}, which "
                                  "cannot be added to existing rows: not a cosim trial database?")
            kind = column.type.compile(dialect=engine.dialect)
            with engine.begin() as c:
                c.execute(sa.text(f"ALTER TABLE {prep.quote(table.name)} ADD COLUMN "
                                  f"{prep.quote(column.name)} {kind}"))


def _sqlite_pragmas(dbapi_conn: Any, _record: Any) -> None:
    cur = dbapi_conn.cursor()
    cur.execute("PRAGMA foreign_keys=ON")
    cur.execute("PRAGMA journal_mode=WAL")  # the experimenter reads while a participant writes
    cur.close()


def _cell(v: Any) -> str:
    if v is None:
        return ""
    if isinstance(v, bool):
        return "1" if v else "0"
    if isinstance(v, float):
        return "" if not math.isfinite(v) else repr(v)
    return str(v)


def export_csv(db: Store | str | Path, path: str | Path) -> Path:
    """Every response as CSV with ``EXPORT_COLUMNS``; returns ``path``."""
    store = db if isinstance(db, Store) else Store(db)
    try:
        rows = store.responses()
    finally:
        if store is not db:
            store.close()
    out = Path(path)
    with out.open("w", newline="") as f:
        write_csv(rows, f)
    return out


def write_csv(rows: list[dict[str, Any]], f: TextIO,
              columns: tuple[str, ...] = EXPORT_COLUMNS) -> None:
    """Responses (``Store.responses()`` rows) as CSV with ``EXPORT_COLUMNS``
    (or live reports, ``Store.live_reports()``, with ``LIVE_EXPORT_COLUMNS``,
    or live commands, ``Store.live_commands()``, with ``LIVE_COMMAND_COLUMNS``);
    text a spreadsheet would run as a formula is neutralised
    (``spreadsheet.safe_cell``), for ``cosim trials export`` and the
    experimenter's download alike."""
    from cosim.trials.spreadsheet import SafeWriter

    w = SafeWriter(f)
    w.writerow(columns)
    for r in rows:
        w.writerow([_cell(r[c]) for c in columns])
