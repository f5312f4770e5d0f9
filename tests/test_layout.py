"""The layout issue 14 asked for, kept: the process model (runbox/) and the hardware layer
(rhal/) load without Django, and the modules of programs/ and robots/ do not import each
other in a circle (a circle makes the import order matter: the first one imported breaks)."""

import ast
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
WEB_APPS = ("programs", "robots")


def test_the_process_model_and_the_hardware_layer_load_without_django():
    modules = sorted(
        f"{package}.{path.stem}"
        for package in ("runbox", "rhal")
        for path in (ROOT / package).glob("*.py")
        if path.stem != "__init__"
    )
    code = (
        "import importlib, sys\n"
        f"for name in {modules!r}:\n"
        "    importlib.import_module(name)\n"
        "print(sorted({m.split('.')[0] for m in sys.modules} & {'django', 'programs', 'robots',"
        " 'robotide', 'channels'}))\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=60,
        env={"PATH": "/usr/bin:/bin"},
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[]", done.stdout


def test_the_simulator_loads_without_django_and_the_real_robots_drivers():
    """rhal.simulator (issue 30) is plain Python: its worlds load and validate (shapely
    included) without Django, the web apps, or the CAN and NXT drivers' modules."""
    modules = sorted(f"rhal.simulator.{p.stem}" for p in (ROOT / "rhal/simulator").glob("*.py"))
    code = (
        "import importlib, sys\n"
        f"for name in {modules!r}:\n"
        "    importlib.import_module(name)\n"
        "from rhal.simulator import worlds\n"
        "for name, doc in worlds.BUILTIN.items():\n"
        "    worlds.World.from_doc(doc)\n"
        "web = {'django', 'programs', 'robots', 'robotide', 'channels', 'worlds'}\n"
        "print(sorted(m for m in sys.modules if m.split('.')[0] in web"
        " or m.startswith(('rhal.canbus', 'rhal.nxt_'))))\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=60,
        env={"PATH": "/usr/bin:/bin"},
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[]", done.stdout


def module_imports(path: Path, package: str) -> set[str]:
    """What a module imports of programs/ and robots/ when it is loaded (its top level, not
    inside functions), as module names."""
    found = set()
    for node in ast.parse(path.read_text()).body:
        if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            base = node.module
            names = [f"{base}.{alias.name}" for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 1:
            base = f"{package}.{node.module}" if node.module else package
            names = [f"{base}.{alias.name}" for alias in node.names]
        elif isinstance(node, ast.Import):
            base, names = None, [alias.name for alias in node.names]
        else:
            continue
        for name in [base, *names]:
            if name and name.split(".")[0] in WEB_APPS and (ROOT / module_file(name)).exists():
                found.add(name)
    return found


def module_file(name: str) -> str:
    return name.replace(".", "/") + ".py"


def import_graph() -> dict[str, set[str]]:
    graph = {}
    for package in WEB_APPS:
        for path in (ROOT / package).glob("*.py"):
            name = f"{package}.{path.stem}"
            graph[name] = module_imports(path, package) - {name}
    return graph


def circle_from(start: str, graph: dict[str, set[str]]) -> list[str] | None:
    """A path of imports from `start` back to itself, if there is one."""
    stack = [(start, [start])]
    seen = set()
    while stack:
        node, path = stack.pop()
        for nxt in graph.get(node, ()):
            if nxt == start:
                return [*path, start]
            if nxt not in seen:
                seen.add(nxt)
                stack.append((nxt, [*path, nxt]))
    return None


def test_programs_and_robots_do_not_import_each_other_in_a_circle():
    graph = import_graph()
    assert graph["robots.runs"] & {"programs.models"}  # the controls: the graph sees imports,
    assert circle_from("a", {"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    circles = [c for name in sorted(graph) if (c := circle_from(name, graph))]
    assert not circles, circles[0]


def test_programs_data_modules_import_nothing_of_robots():
    """Programs and runs as data (models, access) stand alone: robots/ builds on them."""
    graph = import_graph()
    for name in ("programs.models", "programs.access", "programs.runlog"):
        assert not {m for m in graph[name] if m.startswith("robots")}, (name, graph[name])
