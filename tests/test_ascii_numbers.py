"""Numbers from people are written with the ASCII digits 0-9, nothing else.

Python's ``float()`` and ``int()`` read '٢٢' (Arabic-Indic) and '２２' (fullwidth) as 22, so a
value typed with a phone's or an input method's digits would be taken as a number nobody
sees in the text. Every path that reads a number from people's text refuses it in one line
naming the character: command-line options (real ``impctl`` runs), the configuration's
strings (``impctl check-config`` in a subprocess), NIGHTS cells, the MQTT commands and the
``[inputs]`` payloads (the parsers the bridge calls; the daemon with a real broker is in
``test_mqtt_commands_careless``).
"""

from __future__ import annotations

import pandas as pd
import pytest
from cli_fixtures import run_impctl
from test_reliability_input import cli

from impctl.errors import InputError
from impctl.imp import read_nights
from impctl.mqtt.commands import BadCommand, parse_command
from impctl.mqtt.homeassistant.discovery import Limits
from impctl.mqtt.inputs import parse_payload
from impctl.numtext import parse_float, parse_int

ARABIC, FULLWIDTH = "٢٢", "２２"  # both are 22 to float() and int()
LIMITS = Limits(setpoint_min_c=16.0, setpoint_max_c=23.0, comfort_band_k=1.5,
                default_setpoint_c=21.0)


def test_the_checker_refuses_what_float_and_int_take():
    assert float(ARABIC) == int(FULLWIDTH) == 22  # the trap
    for text in (ARABIC, FULLWIDTH, "2٢", "22．5"):
        with pytest.raises(ValueError, match="write numbers with the ASCII digits 0-9"):
            parse_float(text)
    with pytest.raises(ValueError, match=r"'２２' holds '２' \(FULLWIDTH DIGIT TWO\)"):
        parse_int(FULLWIDTH)
    assert parse_float(" 22.5 ") == 22.5 and parse_int("22") == 22


@pytest.mark.parametrize(("argv", "option"), [
    (("fit", "--nights", "n.csv", "--max-nights", FULLWIDTH), "--max-nights"),
    (("fit", "--nights", "n.csv", "--night-gain-w", "٢٠٠"), "--night-gain-w"),
    (("flex", "fit.json", "--t-set", ARABIC), "--t-set"),
    (("demo", "--max-nights", "٥"), "--max-nights"),
    (("demo", "--nights", "２+6"), "--nights"),
    (("demo", "--target", "0.05,０.08"), "--target"),
    (("simulate", "--days", ARABIC), "--days"),
    (("campaign", "next", "--fit", "f.json", "--nights", "n.csv", "--normal-setpoints-c",
      "21,٢٢"), "--normal-setpoints-c"),
    (("campaign", "next", "--fit", "f.json", "--nights", "n.csv", "--forecast-t-out-c",
      "٢"), "--forecast-t-out-c"),
])
def test_cli_options_take_ascii_digits_only(argv, option):
    code, out, err = cli(*argv)
    assert code == 2 and out == "", (code, out, err)
    (line,) = err.splitlines()
    assert line.startswith(f"impctl: {option}: '"), line
    assert "DIGIT" in line and "write numbers with the ASCII digits 0-9" in line, line


def test_export_night_ids_take_ascii_digits_only(tmp_path):
    code, _, err = cli("export", "--db", str(tmp_path / "none.db"), "--out",
                       str(tmp_path / "n.csv"), "--nights", "1,٢")
    assert code == 2
    assert err.strip() == ("impctl: --nights: '1,٢' holds '٢' (ARABIC-INDIC DIGIT TWO): "
                           "write numbers with the ASCII digits 0-9"), err
    assert not (tmp_path / "n.csv").exists()


def test_the_configuration_window_takes_ascii_digits_only(tmp_path):
    cfg = tmp_path / "c.toml"
    cfg.write_text(f'state_dir = "{tmp_path / "s"}"\n[heatpump]\nhost = "192.168.1.50"\n'
                   '[night]\nwindow = "２２:00-05:00"\n')
    result = run_impctl("check-config", "--config", str(cfg))
    assert result.returncode == 2, result.stdout
    assert result.stderr.splitlines() == [
        f"impctl: {cfg}: key 'night.window': '２２:00-05:00' holds '２' (FULLWIDTH DIGIT TWO): "
        "write numbers with the ASCII digits 0-9"]
    assert not (tmp_path / "s").exists()


def test_nights_cells_take_ascii_digits_only(tmp_path):
    path = tmp_path / "n.csv"
    pd.DataFrame({"timestamp": ["2026-01-12T22:00:00+01:00", "2026-01-12T22:05:00+01:00"],
                  "t_air": ["21.5", "٢١.4"], "t_out": ["0", "0"], "q_hc": ["0", "0"]}
                 ).to_csv(path, index=False)
    with pytest.raises(InputError) as exc:
        read_nights(path)
    assert str(exc.value) == (f"{path}: row 3: column 't_air': '٢١.4' holds '٢' "
                              "(ARABIC-INDIC DIGIT TWO): write numbers with the ASCII digits "
                              "0-9")


@pytest.mark.parametrize(("name", "payload"), [
    ("night_setpoint", FULLWIDTH),
    ("night_setpoint", ARABIC),
    ("trigger", '{"setpoint_c": "٢٢"}'),
])
def test_mqtt_commands_take_ascii_digits_only(name, payload):
    with pytest.raises(BadCommand) as exc:
        parse_command(name, payload.encode(), LIMITS, "normal", 21.0)
    assert "write numbers with the ASCII digits 0-9" in str(exc.value)
    assert parse_command(name, payload.translate(str.maketrans("٢２", "22")).encode(),
                         LIMITS, "normal", 21.0).setpoint_c == 22.0


@pytest.mark.parametrize("payload", ["٥٠٠", "５００", "5٠0.5"])
def test_mqtt_inputs_take_ascii_digits_only(payload):
    value, why = parse_payload("house_power_w", payload.encode())
    assert value is None and "write numbers with the ASCII digits 0-9" in why, (value, why)
    assert parse_payload("house_power_w", b"500") == (500.0, None)
