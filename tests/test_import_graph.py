"""Imports flow one way (the layout tells the pipeline): checked on the source, not by review.

The graph is read from every ``import`` in ``src/impctl`` — also the lazy ones inside
functions, which are dependencies all the same — and reduced to edges between the top-level
packages and modules of impctl (``heatpump``, ``modbus``, ``errors`` …).
"""

from __future__ import annotations

import ast
import subprocess
import sys
from collections import defaultdict
from pathlib import Path

import pytest

import impctl

SRC = Path(impctl.__file__).parent
#: The fitting pipeline: each stage may import earlier ones, never a later one.
PIPELINE = ("model", "plant", "imp", "population", "classifiers", "change", "season", "fit",
            "fleet")
#: The device side, transport first.
DEVICE = ("modbus", "kronoterm", "heatpump", "controller", "config", "daemon", "cli")


def _imports(path: Path, module: str) -> set[str]:
    """Absolute names of everything ``module`` (in ``path``) imports."""
    package = module.split(".") if path.name == "__init__.py" else module.split(".")[:-1]
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level:
            base = ".".join(package[:len(package) - node.level + 1]
                            + ([node.module] if node.module else []))
            found.add(base)
            if node.module is None:  # from . import x: x is a module of the package
                found.update(f"{base}.{alias.name}" for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module:
            found.add(node.module)
    return found


def _graph() -> dict[str, set[str]]:
    """Top-level part of impctl → the other top-level parts it imports."""
    edges: dict[str, set[str]] = defaultdict(set)
    for path in SRC.rglob("*.py"):
        parts = path.relative_to(SRC.parent).with_suffix("").parts
        module = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        here = module.split(".")[1] if "." in module else ""
        for name in _imports(path, module):
            top, _, rest = name.partition(".")
            if top == "impctl_sim":
                edges[here].add("impctl_sim")
            elif top == "impctl" and rest and rest.split(".")[0] != here:
                edges[here].add(rest.split(".")[0])
    return edges


@pytest.fixture(scope="module")
def graph() -> dict[str, set[str]]:
    # built when a test asks for it, not at import: every xdist worker imports this module
    return _graph()


def _rooms(package: str) -> dict[str, set[str]]:
    """Inside ``impctl.<package>``: each room (direct subpackage or module; "" for the
    package's own ``__init__``) → the other rooms of the package it imports."""
    edges: dict[str, set[str]] = defaultdict(set)
    for path in (SRC / package).rglob("*.py"):
        parts = path.relative_to(SRC.parent).with_suffix("").parts
        module = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        here = module.split(".")[2] if module.count(".") >= 2 else ""
        for name in _imports(path, module):
            inner = name.split(".")
            if inner[:2] == ["impctl", package] and len(inner) > 2 and inner[2] != here:
                edges[here].add(inner[2])
    return edges


def test_the_graph_is_read_from_the_source(graph):
    # Known edges: if these are not found, the reader is broken and every rule below is void.
    assert {"modbus", "errors"} <= graph["heatpump"]
    assert {"heatpump", "store"} <= graph["controller"]
    assert "model" in graph["fit"]


def test_the_modbus_transport_knows_no_device(graph):
    """impctl.modbus is generic: it knows nothing of Kronoterm, the night or the daemon."""
    assert graph["modbus"] <= {"errors"}


def test_the_device_side_imports_only_towards_the_transport(graph):
    for i, part in enumerate(DEVICE):
        later = set(DEVICE[i + 1:])
        assert not graph[part] & later, f"{part} imports {sorted(graph[part] & later)}"
    assert "impctl_sim" not in set().union(*(graph[p] for p in DEVICE[:-1]))


def test_the_pipeline_imports_only_earlier_stages(graph):
    for i, stage in enumerate(PIPELINE):
        later = set(PIPELINE[i + 1:])
        assert not graph[stage] & later, f"{stage} imports {sorted(graph[stage] & later)}"


def test_the_heat_pump_and_the_model_stay_apart_from_the_fit(graph):
    heavy = {"fit", "classifiers", "population", "fleet", "report"}
    for part in ("modbus", "heatpump", "controller", "daemon", "model"):
        assert not graph[part] & heavy, f"{part} imports {sorted(graph[part] & heavy)}"


def test_no_cycles_between_packages(graph):
    state: dict[str, int] = {}  # 1 on the path, 2 done

    def visit(node: str, path: list[str]) -> None:
        if state.get(node) == 2:
            return
        assert state.get(node) != 1, "import cycle: " + " → ".join([*path, node])
        state[node] = 1
        for nxt in sorted(graph.get(node, ())):
            visit(nxt, [*path, node])
        state[node] = 2

    for node in sorted(graph):
        visit(node, [])


def test_the_simulator_starts_without_pandas():
    """The Modbus simulator (tests and the demo start it often) builds its default weather,
    house and server without pandas: its start costs about half the CPU."""
    code = ("import sys, datetime, impctl_sim.cli, impctl_sim.server; "
            "from impctl.clock import VirtualClock; from impctl_sim import SimConfig; "
            "clock = VirtualClock(datetime.datetime(2026, 1, 12, tzinfo=datetime.UTC), 60.0); "
            "feed = SimConfig().weather_feed(clock); SimConfig().make_plant(clock, 0.0); "
            "print(sorted(m for m in ('torch', 'sklearn', 'pandas') if m in sys.modules), "
            "feed.t_out_c(clock.epoch.timestamp()))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, timeout=60).stdout.split()
    assert out[0] == "[]", out
    assert -30.0 < float(out[1]) < 20.0


def test_the_daemon_process_loads_neither_torch_nor_sklearn_nor_pandas():
    """What ``impctl daemon`` imports keeps torch, scikit-learn and pandas out of its RSS."""
    code = ("import sys, impctl.daemon.service, impctl.daemon.mqtt_link, impctl.controller, "
            "impctl.heatpump, impctl.modbus; "
            "print(sorted(m for m in ('torch', 'sklearn', 'pandas') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, timeout=60).stdout
    assert out.strip() == "[]"



def test_the_plant_rooms_know_only_the_parameters():
    """The building, the hydronics and the instruments are physics side by side: each takes
    its parameters and nothing of the others; only the simulation puts them together, and the
    house file (input) and the simulation know nothing of each other."""
    rooms = _rooms("plant")
    assert {"building", "hydronics", "instruments", "params"} <= rooms["simulation"]
    for room in ("building", "hydronics", "instruments"):
        assert rooms[room] <= {"params"}, f"plant.{room} imports {sorted(rooms[room])}"
    assert rooms["params"] == set()
    assert rooms["housefile"] <= {"params"}



def test_the_cli_audiences_stay_apart():
    """The operator's commands (light, next to the daemon) and the analyst's (heavy libraries
    inside each command) share only the group and the option checks."""
    rooms = _rooms("cli")
    assert "checks" in rooms["analysis"] and {"analysis", "device"} <= rooms[""]
    for room, other in (("device", "analysis"), ("analysis", "device")):
        assert other not in rooms[room], f"cli.{room} imports cli.{other}"
    assert rooms["checks"] == set()


def _modules() -> dict[str, set[str]]:
    """Every module of impctl → the other impctl modules it imports (lazy and typing-only
    imports included: a dependency is a dependency)."""
    paths = {}
    for path in SRC.rglob("*.py"):
        parts = path.relative_to(SRC.parent).with_suffix("").parts
        paths[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    edges: dict[str, set[str]] = defaultdict(set)
    for module, path in paths.items():
        for name in _imports(path, module):
            # ``from .pkg import name`` may name a module of pkg: count the module, if any
            for target in (name, name.rpartition(".")[0]):
                if target in paths and target != module and not module.startswith(target + "."):
                    edges[module].add(target)
                    break
    return edges


def test_no_import_circles_between_modules():
    """Not even inside a package: a circle of modules is one concern split in two, or two
    concerns tangled; either way the layout stops telling which comes first."""
    graph = _modules()
    state: dict[str, int] = {}

    def visit(node: str, path: list[str]) -> None:
        if state.get(node) == 2:
            return
        assert state.get(node) != 1, "import circle: " + " → ".join(
            [*path[path.index(node):], node])
        state[node] = 1
        for nxt in sorted(graph.get(node, ())):
            visit(nxt, [*path, node])
        state[node] = 2

    for node in sorted(graph):
        visit(node, [])


def _commands_in(path: Path) -> set[str]:
    """The names of the commands and groups ``path`` adds to the ``impctl`` group (read from
    its ``@cli.command(…)`` / ``@cli.group(…)`` decorators)."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if not isinstance(node, ast.FunctionDef):
            continue
        for dec in node.decorator_list:
            if (isinstance(dec, ast.Call) and isinstance(dec.func, ast.Attribute)
                    and isinstance(dec.func.value, ast.Name) and dec.func.value.id == "cli"
                    and dec.func.attr in ("command", "group")):
                names.add(dec.args[0].value if dec.args else node.name.replace("_", "-"))
    return names


def test_each_command_is_looked_up_in_the_module_that_adds_it():
    """``impctl NAME`` imports the one module :data:`impctl.cli.COMMAND_MODULES` names: every
    command of the source must be there, in the module whose decorator adds it."""
    from impctl.cli import COMMAND_MODULES

    found = {}
    for path in (SRC / "cli").rglob("*.py"):
        module = ".".join(path.relative_to(SRC / "cli").with_suffix("").parts)
        found.update(dict.fromkeys(_commands_in(path), module))
    assert found == COMMAND_MODULES


def test_a_command_starts_without_the_other_commands_imports():
    """``impctl fit`` does not load the device side (asyncio, the daemon's commands)."""
    code = ("import sys\nfrom impctl.cli import main\ntry:\n    main(['fit', '--help'])\n"
            "except SystemExit:\n    pass\n"
            "print(sorted(m for m in sys.modules if m == 'asyncio' or m.startswith("
            "'impctl.cli.device')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, timeout=60).stdout
    assert out.strip().splitlines()[-1] == "[]"
