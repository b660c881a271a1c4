"""The store's schema: the migrations from an empty file to the current version.

The version is SQLite's ``PRAGMA user_version``; a store is migrated forward on open, one
transaction per version, and a store written by a newer impctl is refused.
"""

from __future__ import annotations

import sqlite3
from pathlib import Path

from ..errors import InputError

# Each entry migrates from version i to i + 1; never edit a released entry, append a new one.
MIGRATIONS: tuple[str, ...] = (
    """
    CREATE TABLE nights (
        id INTEGER PRIMARY KEY,
        kind TEXT NOT NULL CHECK (kind IN ('constrained', 'normal')),
        setpoint_c REAL NOT NULL,
        t_min_c REAL,
        t_max_c REAL,
        window_start TEXT NOT NULL,
        window_end TEXT NOT NULL,
        state TEXT NOT NULL,
        source TEXT NOT NULL,
        valid INTEGER,
        reasons TEXT NOT NULL DEFAULT '[]',
        started TEXT,
        ended TEXT
    );
    CREATE TABLE samples (
        night_id INTEGER NOT NULL REFERENCES nights(id),
        ts TEXT NOT NULL,
        t_air_c REAL, t_out_c REAL, q_hc_w REAL, p_el_w REAL, t_supply_c REAL, t_return_c REAL,
        working_function INTEGER, defrost INTEGER, error_bits INTEGER, loop_mode INTEGER,
        setpoint_c REAL, dhw_active INTEGER,
        PRIMARY KEY (night_id, ts)
    );
    CREATE TABLE journal (
        id INTEGER PRIMARY KEY,
        night_id INTEGER REFERENCES nights(id),
        register TEXT NOT NULL,
        address INTEGER NOT NULL,
        raw_value INTEGER NOT NULL,
        recorded TEXT NOT NULL,
        restored TEXT
    );
    CREATE INDEX journal_pending ON journal(register) WHERE restored IS NULL;
    CREATE TABLE requests (
        id INTEGER PRIMARY KEY,
        kind TEXT NOT NULL CHECK (kind IN ('constrained', 'normal')),
        setpoint_c REAL,
        run_when TEXT NOT NULL CHECK (run_when IN ('now', 'tonight')),
        created TEXT NOT NULL,
        taken TEXT,
        extra TEXT NOT NULL DEFAULT '{}'
    );
    CREATE TABLE campaign (
        seq INTEGER PRIMARY KEY,
        kind TEXT NOT NULL,
        setpoint_c REAL NOT NULL,
        night_id INTEGER REFERENCES nights(id)
    );
    CREATE TABLE fits (
        id INTEGER PRIMARY KEY,
        created TEXT NOT NULL,
        nights TEXT NOT NULL,
        result TEXT NOT NULL
    );
    CREATE TABLE events (
        id INTEGER PRIMARY KEY,
        ts TEXT NOT NULL,
        level TEXT NOT NULL,
        message TEXT NOT NULL
    );
    """,
    # 2: requests expire and can be cancelled; a journal entry can end because the owner
    # changed the register mid-night (kept, not overwritten) instead of being restored.
    """
    ALTER TABLE requests ADD COLUMN expires TEXT;
    ALTER TABLE requests ADD COLUMN outcome TEXT;
    ALTER TABLE journal ADD COLUMN outcome TEXT;
    """,
    # 3: household commands (abort, skip_tonight) queued for the daemon, e.g. over MQTT.
    """
    CREATE TABLE commands (
        id INTEGER PRIMARY KEY,
        name TEXT NOT NULL CHECK (name IN ('abort', 'skip_tonight')),
        source TEXT NOT NULL,
        created TEXT NOT NULL,
        taken TEXT
    );
    """,
    # 4: the adaptive campaign (issue 18). A fit keeps how many valid nights it used and the
    # predictions of `impctl campaign next` made from it; each night's decision (run, skip,
    # stop) is kept with its reason and the forecast it used.
    """
    ALTER TABLE fits ADD COLUMN night_count INTEGER;
    UPDATE fits SET night_count = json_array_length(nights);
    ALTER TABLE fits ADD COLUMN candidates TEXT;
    CREATE TABLE decisions (
        id INTEGER PRIMARY KEY,
        created TEXT NOT NULL,
        act TEXT,
        action TEXT NOT NULL CHECK (action IN ('run', 'skip', 'stop')),
        kind TEXT,
        setpoint_c REAL,
        reason TEXT NOT NULL,
        reached INTEGER NOT NULL DEFAULT 0,
        forecast_t_out_c REAL,
        forecast_source TEXT
    );
    """,
    # 5: what the house's own sensors said at each sample ([inputs] over MQTT): the value with
    # its age, missing when stale or malformed. night_id NULL: a reading between nights (the
    # outdoor-sensor check at installation). t_out_c is the heat pump's sensor at that moment.
    """
    CREATE TABLE house_inputs (
        night_id INTEGER REFERENCES nights(id),
        ts TEXT NOT NULL,
        house_power_w REAL, house_power_age_s REAL,
        p_house_w REAL,
        t_rooms_c REAL, t_rooms_age_s REAL, rooms INTEGER,
        t_out_ref_c REAL, t_out_ref_age_s REAL,
        occupants REAL, occupants_age_s REAL,
        t_out_c REAL
    );
    CREATE UNIQUE INDEX house_inputs_sample ON house_inputs(night_id, ts);
    """,
    # 6: the owner's own days and nights, recorded read-only between IMP nights: a night of
    # kind 'owner' per local day (12:00 to 12:00; its setpoint, the owner's, may be unknown)
    # whose samples are the means of the snapshots in each [ts, ts + record.interval_s). The
    # nights table is recreated for its kind constraint (foreign keys off meanwhile, see
    # migrate()); every row and id is kept. New sample columns: the loop-1 calculated flow
    # target (2128), the DHW share of a row, the heating system switch (2012) and how many
    # snapshots a row averages (NULL: an IMP night's sample, one snapshot).
    """
    CREATE TABLE nights_6 (
        id INTEGER PRIMARY KEY,
        kind TEXT NOT NULL CHECK (kind IN ('constrained', 'normal', 'owner')),
        setpoint_c REAL,
        t_min_c REAL,
        t_max_c REAL,
        window_start TEXT NOT NULL,
        window_end TEXT NOT NULL,
        state TEXT NOT NULL,
        source TEXT NOT NULL,
        valid INTEGER,
        reasons TEXT NOT NULL DEFAULT '[]',
        started TEXT,
        ended TEXT
    );
    INSERT INTO nights_6 (id, kind, setpoint_c, t_min_c, t_max_c, window_start, window_end,
                          state, source, valid, reasons, started, ended)
        SELECT id, kind, setpoint_c, t_min_c, t_max_c, window_start, window_end, state, source,
               valid, reasons, started, ended FROM nights;
    DROP TABLE nights;
    ALTER TABLE nights_6 RENAME TO nights;
    CREATE INDEX nights_kind ON nights(kind, window_start);
    ALTER TABLE samples ADD COLUMN t_flow_target_c REAL;
    ALTER TABLE samples ADD COLUMN dhw_share REAL;
    ALTER TABLE samples ADD COLUMN system_on INTEGER;
    ALTER TABLE samples ADD COLUMN snapshots INTEGER;
    """,
    # 7: beside a pending journal entry, what impctl last wrote into its register and read
    # back (raw; NULL while a write is unconfirmed): a restart tells the owner's change made
    # while impctl was down from impctl's own value. NULL in older rows: the owner's value
    # is restored, as before.
    """
    ALTER TABLE journal ADD COLUMN confirmed_raw INTEGER;
    """,
)
SCHEMA_VERSION = len(MIGRATIONS)


def migrate(db: sqlite3.Connection, path: Path) -> None:
    """Bring the open store ``db`` (file ``path``, for messages) to :data:`SCHEMA_VERSION`."""
    version = db.execute("PRAGMA user_version").fetchone()[0]
    if version > SCHEMA_VERSION:
        raise InputError(
            f"database schema {version} is newer than this impctl ({SCHEMA_VERSION}); "
            "upgrade impctl", path)
    if version >= SCHEMA_VERSION:
        return
    # A table other tables refer to is recreated (SQLite's way to change a constraint) with
    # foreign keys off: with them on, dropping it would delete-check every referring row.
    # The pragma is a no-op inside a transaction, so it is set around them, and every
    # reference is checked before each commit instead.
    keys_on = bool(db.execute("PRAGMA foreign_keys").fetchone()[0])
    db.execute("PRAGMA foreign_keys=OFF")
    try:
        for target in range(version + 1, SCHEMA_VERSION + 1):
            db.execute("BEGIN IMMEDIATE")
            try:
                for statement in MIGRATIONS[target - 1].split(";"):
                    if statement.strip():
                        db.execute(statement)
                broken = db.execute("PRAGMA foreign_key_check").fetchone()
                if broken is not None:
                    raise sqlite3.IntegrityError(
                        f"migration {target} would leave a row of {broken[0]} pointing nowhere")
                db.execute(f"PRAGMA user_version = {target}")
                db.execute("COMMIT")
            except BaseException:
                db.execute("ROLLBACK")
                raise
    finally:
        if keys_on:
            db.execute("PRAGMA foreign_keys=ON")
