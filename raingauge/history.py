"""The instrument's history: one SQLite row per record (sqlite-utils, WAL).

Table ``records`` has the columns of :func:`firmware_interface.fields.sql_columns`
(all record fields, the quality flags, the camera settings and the 32-class
DSD) plus an integer primary key ``id``; table ``settings`` keeps key/value
state that must survive a restart (accumulation and rain duration since the
last reset, the Modbus unit id, the window).  Each :meth:`History.append`
is one transaction committed with ``synchronous=FULL``, so a killed process
or a power cut loses no committed record, and WAL keeps readers (the
``sqlite-utils`` CLI, ``raingauge export``) from blocking the writer.

A full disk makes :meth:`History.append` raise :class:`StorageFull`; the
caller keeps the record and tries again later (see
:mod:`raingauge.instrument.loop`).
"""

from __future__ import annotations

import csv
import datetime as dt
import json
import math
import sqlite3
import threading
import time
from pathlib import Path
from typing import IO, Any, Iterator

from firmware_interface.fields import csv_header, sql_columns, sql_row
from raingauge.errors import ConfigError, InputError, RaingaugeError

__all__ = ["History", "StorageFull", "parse_iso", "TABLE", "SETTINGS_TABLE"]

TABLE = "records"
SETTINGS_TABLE = "settings"


class StorageFull(RaingaugeError, OSError):
    """The history database cannot be written (disk full, read-only, I/O error)."""


def parse_iso(text: str | None, *, name: str = "time") -> float | None:
    """ISO 8601 date or date-time -> seconds since the epoch [s]; naive means UTC."""
    if text is None or text == "":
        return None
    try:
        stamp = dt.datetime.fromisoformat(text.strip().replace("Z", "+00:00").replace(" ", "T"))
    except ValueError:
        raise InputError(f"{name} {text!r} is not an ISO 8601 time. Fix: e.g. 2026-11-22 or "
                         "2026-11-22T09:30:00Z") from None
    if stamp.tzinfo is None:
        stamp = stamp.replace(tzinfo=dt.timezone.utc)
    return stamp.timestamp()


class History:
    """Append-only record store.

    Parameters
    ----------
    path : database file (created with its folder when missing)
    retention_days : rows older than this [days] are deleted (``None`` keeps all)
    readonly : open for reading only (export, plot)
    """

    def __init__(self, path: str | Path, *, retention_days: float | None = None, readonly: bool = False):
        import sqlite_utils

        self.path = Path(path)
        if retention_days is not None and not retention_days > 0:
            raise ConfigError(f"history retention {retention_days!r} days must be > 0. Fix: e.g. retention_days = 365")
        self.retention_days = retention_days
        self._lock = threading.Lock()
        self._appends = 0
        if readonly:
            if not self.path.exists():
                raise InputError(f"{self.path}: no such database. Fix: give the --db that `raingauge run` writes")
            try:
                conn = sqlite3.connect(f"file:{self.path}?mode=ro", uri=True, check_same_thread=False, timeout=10)
            except sqlite3.Error as exc:
                raise InputError(f"{self.path}: cannot open the history database ({exc}). "
                                 "Fix: give the --db that `raingauge run` writes") from None
        else:
            try:
                self.path.parent.mkdir(parents=True, exist_ok=True)
                conn = sqlite3.connect(str(self.path), check_same_thread=False, timeout=10)
            except (OSError, sqlite3.Error) as exc:
                raise ConfigError(f"{self.path}: cannot open the history database ({exc}). "
                                  "Fix: choose a writable path with --db or [history] path") from None
        self.db = sqlite_utils.Database(conn)
        if not readonly:
            try:
                self.db.enable_wal()
                self.db.execute("PRAGMA synchronous=FULL")
                self._create()
            except sqlite3.DatabaseError as exc:
                raise ConfigError(f"{self.path}: not a usable SQLite database ({exc}). "
                                  "Fix: move the file away or point --db elsewhere") from None
        else:
            try:
                tables = self.db.table_names()
            except sqlite3.DatabaseError as exc:
                self.db.close()
                raise InputError(f"{self.path}: not a usable SQLite database ({exc}). "
                                 "Fix: give the --db that `raingauge run` writes") from None
            if TABLE not in tables:
                raise InputError(f"{self.path}: holds no `{TABLE}` table. Fix: give a database written by `raingauge run`")

    def _create(self) -> None:
        cols = sql_columns()
        table = self.db[TABLE]
        if not table.exists():
            table.create({"id": int, **cols}, pk="id")
            table.create_index(["time_unix"], if_not_exists=True)
        else:
            have = {c.name for c in table.columns}
            for name, typ in cols.items():
                if name not in have:  # a newer field table: add the column
                    table.add_column(name, typ)
        if not self.db[SETTINGS_TABLE].exists():
            self.db[SETTINGS_TABLE].create({"key": str, "value": str}, pk="key")

    # ------------------------------------------------------------------ writing
    def append(self, record: dict[str, Any], *, settings: dict[str, Any] | None = None) -> int:
        """Store one record (and optional settings) in one committed transaction; return its id.

        Raises :class:`StorageFull` when the database cannot be written.
        """
        row = sql_row(record)
        with self._lock:
            try:
                with self.db.atomic():
                    cur = self.db.execute(
                        f"INSERT INTO [{TABLE}] ({', '.join('[' + c + ']' for c in row)}) "
                        f"VALUES ({', '.join('?' for _ in row)})", list(row.values()))
                    rowid = cur.lastrowid
                    for key, value in (settings or {}).items():
                        self.db.execute(f"INSERT INTO [{SETTINGS_TABLE}] (key, value) VALUES (?, ?) "
                                        "ON CONFLICT(key) DO UPDATE SET value = excluded.value",
                                        [key, json.dumps(value)])
            except sqlite3.OperationalError as exc:
                raise StorageFull(f"{self.path}: cannot store the record ({exc})") from exc
            except sqlite3.DatabaseError as exc:
                raise StorageFull(f"{self.path}: database error ({exc})") from exc
            self._appends += 1
        if self.retention_days is not None and self._appends % 60 == 1:
            self.prune()
        return rowid

    def set_settings(self, **values: Any) -> None:
        """Persist settings (JSON values)."""
        with self._lock:
            try:
                with self.db.atomic():
                    for key, value in values.items():
                        self.db.execute(f"INSERT INTO [{SETTINGS_TABLE}] (key, value) VALUES (?, ?) "
                                        "ON CONFLICT(key) DO UPDATE SET value = excluded.value",
                                        [key, json.dumps(value)])
            except sqlite3.DatabaseError as exc:
                raise StorageFull(f"{self.path}: cannot store settings ({exc})") from exc

    def settings(self) -> dict[str, Any]:
        """All persisted settings."""
        if SETTINGS_TABLE not in self.db.table_names():
            return {}
        return {k: json.loads(v) for k, v in self.db.execute(f"SELECT key, value FROM [{SETTINGS_TABLE}]").fetchall()}

    def prune(self, now: float | None = None) -> int:
        """Delete rows older than the retention; return how many."""
        if self.retention_days is None:
            return 0
        cutoff = (time.time() if now is None else now) - self.retention_days * 86400.0
        with self._lock:
            try:
                cur = self.db.execute(f"DELETE FROM [{TABLE}] WHERE time_unix < ?", [cutoff])
            except sqlite3.DatabaseError as exc:
                raise StorageFull(f"{self.path}: cannot prune ({exc})") from exc
            return cur.rowcount

    # ------------------------------------------------------------------ reading
    def count(self) -> int:
        return self.db.execute(f"SELECT count(*) FROM [{TABLE}]").fetchone()[0]

    def rows(self, start: float | None = None, end: float | None = None) -> Iterator[dict[str, Any]]:
        """Rows (dicts of columns) with start <= time_unix <= end, oldest first."""
        where, params = [], []
        if start is not None:
            where.append("time_unix >= ?")
            params.append(start)
        if end is not None:
            where.append("time_unix <= ?")
            params.append(end)
        cols = csv_header()
        sql = f"SELECT {', '.join('[' + c + ']' for c in cols)} FROM [{TABLE}]"
        if where:
            sql += " WHERE " + " AND ".join(where)
        sql += " ORDER BY time_unix, id"
        for values in self.db.execute(sql, params):
            yield dict(zip(cols, values))

    def export_csv(self, out: IO[str], *, start: float | None = None, end: float | None = None) -> int:
        """Write the header and the rows in [start, end] as CSV; return the number of rows."""
        writer = csv.writer(out, lineterminator="\n")
        header = csv_header()
        writer.writerow(header)
        n = 0
        for row in self.rows(start, end):
            writer.writerow(["" if row[c] is None else (repr(row[c]) if isinstance(row[c], float) and math.isfinite(row[c]) else row[c]) for c in header])
            n += 1
        return n

    def integrity_ok(self) -> bool:
        return self.db.execute("PRAGMA integrity_check").fetchone()[0] == "ok"

    def close(self) -> None:
        with self._lock:
            try:
                self.db.close()
            except sqlite3.Error:
                pass
