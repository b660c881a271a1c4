"""Issue 12, items 1, 10 and 11 for ``impctl export``: it never writes onto the store (or any
existing file without ``--force``), never creates directories, never writes an empty file for
a night that does not exist, and never shows a traceback; ``state_dir`` under /proc or pointing
at a file is one line and exit status 2.

A real SQLite store with a night, samples and a pending restore journal entry; ``impctl`` runs
in-process through its console entry point (``main``) and, where a traceback would show, as a
real subprocess.
"""

from __future__ import annotations

import hashlib
from datetime import UTC, datetime, timedelta
from pathlib import Path

import pytest
from cli_fixtures import run_impctl
from daemon_fixtures import run_cli, write_config
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from impctl.cli import main
from impctl.store import Sample, Store

START = datetime(2026, 1, 12, 21, 0, tzinfo=UTC)


def _store(state: Path) -> Path:
    """A store with one valid normal night (20 samples) and the owner's journaled setpoint."""
    state.mkdir(parents=True, exist_ok=True)
    db = state / "impctl.db"
    with Store(db) as store:
        nid = store.create_night("normal", 22.0, START, START + timedelta(hours=7))
        for i in range(20):
            store.add_sample(Sample(nid, START + timedelta(minutes=5 * i), t_air_c=22.0,
                                    t_out_c=0.0, q_hc_w=2000.0 + i))
        store.set_night_state(nid, "done")
        store.assess_night(nid, True, ["window ended"])
        store.journal_record(None, "loop1_setpoint", 2186, 210)
    return db


def _config(tmp_path: Path, state: Path) -> Path:
    return write_config(tmp_path / "config.toml", {
        "state_dir": str(state), "heatpump": {"host": "192.168.1.50"}})


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _run(capsys, *args: str) -> tuple[int, str, str]:
    with pytest.raises(SystemExit) as exc:
        main([*args])
        raise SystemExit(0)
    out = capsys.readouterr()
    return exc.value.code or 0, out.out, out.err


def _intact(db: Path) -> None:
    with Store(db, create=False) as store:
        assert store.integrity_check() == "ok"
        assert [n.id for n in store.nights()] == [1] and store.sample_count(1) == 20
        [entry] = store.journal_pending()
        assert (entry.register, entry.raw_value) == ("loop1_setpoint", 210)


def test_export_onto_the_store_is_refused_and_the_journal_survives(tmp_path, capsys):
    state = tmp_path / "state"
    db = _store(state)
    config = _config(tmp_path, state)
    # Exactly what the issue ran (daemon stopped), then the same with --force, through a
    # path with "..", and onto the write counters (another SQLite file in the state dir).
    (state / "writes.db").write_bytes(b"SQLite format 3\0" + bytes(100))
    for target, force in ((db, ()), (db, ("--force",)),
                          (state / ".." / "state" / "impctl.db", ("--force",)),
                          (Path(f"{db}-wal"), ("--force",)),
                          (state / "writes.db", ("--force",))):
        code, out, err = _run(capsys, "export", "--config", str(config), "--out", str(target),
                              *force)
        assert code == 2 and out == "", (target, out, err)
        assert len(err.splitlines()) == 1 and "never writes onto" in err, err
        _intact(db)
    # Every later command still reads the store.
    code, out, _ = _run(capsys, "nights", "--config", str(config))
    assert code == 0 and "normal" in out


def test_fit_and_simulate_never_write_onto_the_store(tmp_path, capsys):
    # "No command may destroy the journal": the other commands that write files refuse an
    # SQLite database (or its -wal side file) as their output, before doing any work.
    state = tmp_path / "state"
    db = _store(state)
    nights = tmp_path / "nights.csv"
    nights.write_text("timestamp,t_air,t_out,q_hc\n")
    for args in (("fit", "--nights", str(nights), "--json", str(db)),
                 ("fit", "--nights", str(nights), "--plot", f"{db}-wal"),
                 ("simulate", "--out", str(db))):
        code, out, err = _run(capsys, *args)
        assert code == 2 and out == "", (args, out, err)
        assert len(err.splitlines()) == 1 and "never writes onto" in err, err
        _intact(db)


def test_existing_file_needs_force_directory_and_missing_dir_refused(tmp_path, capsys):
    state = tmp_path / "state"
    _store(state)
    config = _config(tmp_path, state)
    mine = tmp_path / "mine.csv"
    mine.write_text("my own data\n")
    code, _, err = _run(capsys, "export", "--config", str(config), "--out", str(mine))
    assert code == 2 and "exists; add --force" in err
    assert mine.read_text() == "my own data\n"
    code, out, _ = _run(capsys, "export", "--config", str(config), "--out", str(mine),
                        "--force")
    assert code == 0 and out.startswith("wrote 20 samples")
    assert mine.read_text().startswith("timestamp,t_air,t_out,q_hc")
    # A directory and a directory that does not exist: one line, nothing created.
    code, _, err = _run(capsys, "export", "--config", str(config), "--out", str(tmp_path))
    assert code == 2 and "is a directory" in err
    missing = tmp_path / "nonexistent" / "dir" / "h.csv"
    code, _, err = _run(capsys, "export", "--config", str(config), "--out", str(missing))
    assert code == 2 and "does not exist" in err
    assert not (tmp_path / "nonexistent").exists()
    # A night that does not exist: exit 2, no (empty) file written.
    out99 = tmp_path / "n99.csv"
    code, _, err = _run(capsys, "export", "--config", str(config), "--nights", "99", "--out",
                        str(out99))
    assert code == 2 and "no such night(s) in the store: 99" in err
    assert not out99.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["config.toml", "mine.csv", "state"]


@settings(max_examples=25, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(target=st.sampled_from(["store", "wal", "journal-db", "dir", "missing-dir", "existing",
                               "new", "state-dir"]),
       force=st.booleans(), nights=st.sampled_from([None, "1", "99", "1,99"]))
def test_export_never_loses_data_property(tmp_path_factory, capsys, target, force, nights):
    tmp = tmp_path_factory.mktemp("exp")
    state = tmp / "state"
    db = _store(state)
    config = _config(tmp, state)
    existing = tmp / "existing.csv"
    existing.write_text("keep\n")
    out = {"store": db, "wal": Path(f"{db}-wal"), "journal-db": state / "impctl.db",
           "dir": tmp, "missing-dir": tmp / "no" / "h.csv", "existing": existing,
           "new": tmp / "new.csv", "state-dir": state}[target]
    before = {p: _digest(p) for p in (db, existing)}
    args = ["export", "--config", str(config), "--out", str(out)]
    args += ["--force"] if force else []
    args += ["--nights", nights] if nights else []
    code, stdout, err = _run(capsys, *args)
    allowed = target == "new" or (target == "existing" and force)
    if allowed and nights in (None, "1"):
        assert code == 0 and stdout.startswith("wrote 20 samples"), err
    else:
        assert code == 2 and len(err.splitlines()) == 1 and "Traceback" not in err
    # The store always survives whole; a file the user had is only replaced with --force.
    _intact(db)
    if not (target == "existing" and force and code == 0):
        assert _digest(existing) == before[existing]
    assert not (tmp / "no").exists()
    if code == 2 and target == "new":
        assert not out.exists()


@pytest.mark.parametrize("where", ["proc", "file"])
def test_state_dir_under_proc_or_a_file_is_one_line(tmp_path, where):
    state = "/proc/impctl" if where == "proc" else str(tmp_path / "a-file")
    (tmp_path / "a-file").write_text("not a directory\n")
    config = write_config(tmp_path / "c.toml", {"state_dir": state,
                                                "heatpump": {"host": "192.168.1.50"}})
    for args in (("daemon",), ("trigger", "--kind", "normal", "--tonight"),
                 ("export", "--out", str(tmp_path / "x.csv")), ("status",), ("nights",),
                 ("check-config",)):
        # the daemon in its own process; the other commands' line is checked in this one
        done = (run_cli(*args, "--config", str(config), timeout_s=60) if args == ("daemon",)
                else run_impctl(*args, "--config", str(config)))
        assert done.returncode == 2, (args, done.stderr)
        assert "Traceback" not in done.stderr and len(done.stderr.splitlines()) == 1, (
            args, done.stderr)
        assert state in done.stderr or str(tmp_path / "a-file") in done.stderr
    assert not (tmp_path / "x.csv").exists()


@pytest.mark.parametrize("emitter", ["underfloor", None])
def test_the_export_carries_the_emitter_the_installer_declared(tmp_path, capsys, emitter):
    """[fit] emitter goes with the nights (the NIGHTS column ``emitter``): a fleet reading the
    export knows what the installer knows; without it, no column."""
    from impctl.imp.files.nights_csv import read_nights

    state = tmp_path / "state"
    _store(state)
    mapping = {"state_dir": str(state), "heatpump": {"host": "192.168.1.50"}}
    if emitter is not None:
        mapping["fit"] = {"emitter": emitter}
    config = write_config(tmp_path / "config.toml", mapping)
    out = tmp_path / "nights.csv"
    code, _, err = _run(capsys, "export", "--config", str(config), "--out", str(out))
    assert code == 0, err
    header = out.read_text().splitlines()[0].split(",")
    assert ("emitter" in header) == (emitter is not None)
    assert {n.emitter for n in read_nights(out, "UTC")} == {emitter or ""}
