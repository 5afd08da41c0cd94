"""The house rules a tool checks: the import contract of pyproject.toml ([tool.importlinter], run
by ``lint-imports`` in scripts/run_tests.sh) covers every top-level module of roft_sim and holds,
and no function of roft_sim is longer than 80 lines."""

from __future__ import annotations

import ast
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
PACKAGE = REPO / "roft_sim"

MAX_FUNCTION_LINES = 80
"""A function's length: from its first statement after the docstring to its last line (comments
and blank lines included, the signature and docstring not)."""


def _importlinter() -> dict:
    with (REPO / "pyproject.toml").open("rb") as f:
        return tomllib.load(f)["tool"]["importlinter"]


def _contract(contract_id: str) -> dict:
    contracts = {c["id"]: c for c in _importlinter()["contracts"]}
    assert contract_id in contracts, f"no contract {contract_id!r}; have {sorted(contracts)}"
    return contracts[contract_id]


def _layer_names(layers: list[str]) -> tuple[set[str], set[str]]:
    """(every name in ``layers``, the optional ones): ``a | b`` siblings, ``(c)`` optional."""
    names, optional = set(), set()
    for layer in layers:
        for part in layer.replace(":", "|").split("|"):
            name = part.strip()
            if name.startswith("(") and name.endswith(")"):
                name = name[1:-1].strip()
                optional.add(name)
            names.add(name)
    return names, optional


def _top_level_modules() -> set[str]:
    """The modules and packages directly inside roft_sim/, as import-linter sees them."""
    modules = {p.stem for p in PACKAGE.glob("*.py") if p.stem != "__init__"}
    packages = {p.parent.name for p in PACKAGE.glob("*/__init__.py")}
    return modules | packages


def test_the_layers_contract_names_every_top_level_module():
    layers = _contract("layers")
    assert layers["type"] == "layers"
    assert layers["containers"] == ["roft_sim"]
    # import-linter itself then fails on a module that no layer names
    assert layers["exhaustive"] is True
    ignored = set(layers.get("exhaustive_ignores", []))
    assert ignored == {"__main__"}
    names, optional = _layer_names(layers["layers"])
    on_disk = _top_level_modules()
    assert on_disk - ignored <= names, f"not in any layer: {sorted(on_disk - ignored - names)}"
    assert names - optional <= on_disk, f"layers of no module: {sorted(names - optional - on_disk)}"
    order = [layer.strip() for layer in layers["layers"]]
    assert order[0] == "cli" and order[-1] == "errors"
    # the floors, bottom to top
    floors = ["geometry", "records", "trajectories", "sensors", "scene", "render", "generation"]
    floors += ["harness", "cli"]
    rank = {n: i for i, layer in enumerate(order) for n in _layer_names([layer])[0]}
    assert [rank[f] for f in floors] == sorted((rank[f] for f in floors), reverse=True)
    assert rank["trackers"] > rank["harness"] and rank["metrics"] > rank["harness"]


def test_the_other_contracts_say_what_the_architecture_promises():
    assert _importlinter()["root_package"] == "roft_sim"
    assert _importlinter()["include_external_packages"] is True  # so that mujoco can be named
    trackers = _contract("trackers")
    assert trackers["type"] == "forbidden" and trackers["source_modules"] == ["roft_sim.trackers"]
    assert set(trackers["forbidden_modules"]) >= {"mujoco", "roft_sim.harness", "roft_sim.metrics"}
    cli = _contract("cli")
    assert cli["type"] == "protected" and cli["protected_modules"] == ["roft_sim.cli"]
    assert cli["allowed_importers"] == ["roft_sim.__main__"]
    acyclic = _contract("acyclic")
    assert acyclic["type"] == "acyclic_siblings" and acyclic["ancestors"] == ["roft_sim"]
    mujoco = _contract("mujoco")
    assert mujoco["forbidden_modules"] == ["mujoco"]
    layers = [layer.strip() for layer in _contract("layers")["layers"]]
    below_render = layers[next(i for i, x in enumerate(layers) if "render" in x) + 1 :]
    below, _ = _layer_names(below_render)
    assert {m.removeprefix("roft_sim.") for m in mujoco["source_modules"]} >= below


def test_the_test_command_checks_the_contracts():
    lines = (REPO / "scripts" / "run_tests.sh").read_text().splitlines()
    commands = [line.strip() for line in lines if line.strip() and not line.startswith("#")]

    def position(word: str) -> int:
        return next(i for i, c in enumerate(commands) if word in c)

    assert position("lint-imports") < position("-m pytest")
    assert position("-m mypy") < position("-m pytest")  # started beside the tests ...
    assert position("-m pytest") < position('wait "$mypy_pid"')  # ... and its status decides
    assert any(c.startswith("exit 1") for c in commands[position('wait "$mypy_pid"') :])


def test_lint_imports_keeps_every_contract():
    pytest.importorskip("importlinter", reason="import-linter is in the dev extra")
    exe = shutil.which("lint-imports", path=str(Path(sys.executable).parent))
    assert exe is not None, "lint-imports is not next to this Python"
    proc = subprocess.run(
        [exe, "--no-cache"], cwd=REPO, capture_output=True, text=True, timeout=120
    )
    assert proc.returncode == 0, proc.stdout[-4000:] + proc.stderr[-2000:]
    assert "0 broken" in proc.stdout


def _code_lines(node: ast.FunctionDef | ast.AsyncFunctionDef) -> int:
    body = node.body
    first = body[0]
    if (
        len(body) > 1
        and isinstance(first, ast.Expr)
        and isinstance(first.value, ast.Constant)
        and isinstance(first.value.value, str)
    ):
        first = body[1]
    assert node.end_lineno is not None
    return node.end_lineno - first.lineno + 1


def _function_lengths(path: Path) -> dict[str, int]:
    """``qualified name -> code lines`` of every function in ``path`` (methods and nested
    functions included)."""
    lengths: dict[str, int] = {}

    def visit(node: ast.AST, prefix: str) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef):
                lengths[prefix + child.name] = _code_lines(child)
                visit(child, f"{prefix}{child.name}.")
            elif isinstance(child, ast.ClassDef):
                visit(child, f"{prefix}{child.name}.")
            else:
                visit(child, prefix)

    visit(ast.parse(path.read_text(encoding="utf-8")), "")
    return lengths


def _long_functions() -> dict[str, int]:
    out = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(REPO).as_posix()
        for name, lines in _function_lengths(path).items():
            if lines > MAX_FUNCTION_LINES:
                out[f"{rel}::{name}"] = lines
    return out


def test_the_length_scan_sees_a_long_function(tmp_path):
    body = "\n".join(f"    x{i} = {i}" for i in range(MAX_FUNCTION_LINES + 1))
    source = f'class A:\n    def f(self):\n        """Doc."""\n{body.replace("    ", "        ")}\n'
    path = tmp_path / "m.py"
    path.write_text(source + "\n\ndef g():\n    return 1\n")
    assert _function_lengths(path) == {"A.f": MAX_FUNCTION_LINES + 1, "g": 1}


def test_no_function_is_longer_than_80_lines():
    offenders = _long_functions()
    assert not offenders, "functions over 80 lines (split them): " + ", ".join(
        f"{name} ({n})" for name, n in sorted(offenders.items())
    )
