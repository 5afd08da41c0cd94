"""The CLI entry point: exit codes, help, logging that survives swapped stderr."""

from __future__ import annotations

import argparse
import importlib
import io
import logging
import pkgutil
import subprocess
import sys

import pytest

import roft_sim.cli
from roft_sim.cli import VERBS, build_parser, main


def test_help_and_no_verb_exit_codes(capsys):
    assert main(["--help"]) == 0
    assert "trackers" in capsys.readouterr().out
    assert main([]) == 2
    assert main(["no-such-verb"]) == 2


def test_the_verb_table_names_every_sub_parser_in_help_order():
    parser = build_parser()
    (sub,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    assert list(sub.choices) == [name for name, _ in VERBS]
    assert len(VERBS) == len({name for name, _ in VERBS}) >= 12


def test_every_verb_module_is_in_the_verb_table():
    """A module of roft_sim.cli with a ``register`` is a verb: it must be listed in VERBS."""
    listed = {register.__module__ for _, register in VERBS}
    for info in pkgutil.iter_modules(roft_sim.cli.__path__):
        module = importlib.import_module(f"roft_sim.cli.{info.name}")
        if hasattr(module, "register"):
            assert module.__name__ in listed, module.__name__


def test_logging_follows_the_current_stderr(monkeypatch):
    assert main(["-q", "trackers"]) == 0
    replaced = io.StringIO()
    monkeypatch.setattr(sys, "stderr", replaced)
    logging.getLogger("roft_sim.test").warning("after the swap")
    assert "after the swap" in replaced.getvalue()


@pytest.mark.parametrize("argv", [["-m", "roft_sim", "--version"]])
def test_python_dash_m_runs_the_cli(argv):
    out = subprocess.run([sys.executable, *argv], capture_output=True, text=True, check=True)
    assert out.stdout.startswith("roft-sim ")


def test_importing_the_cli_leaves_trimesh_and_the_network_modules_out():
    """Every verb imports roft_sim.cli: trimesh (0.2-0.5 s, only needed to read mesh files) and
    the download modules of ``assets install`` load only in the code that uses them."""
    code = (
        "import sys, roft_sim.cli\n"
        "print(sorted(m for m in ('trimesh', 'http.client', 'urllib.request', 'tarfile')"
        " if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def _options(parser: argparse.ArgumentParser, prefix: str = ""):
    """Every option of ``parser`` and its sub-parsers: ``(command path, option, action)``."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from _options(sub, f"{prefix} {name}".strip())
        else:
            for option in action.option_strings:
                yield prefix, option, action


def test_the_cli_choices_are_the_library_sets():
    """The CLI spells the invalid-estimate policies, depth encodings and twist conventions as
    literals (importing the metrics and bag modules would slow every verb's start); each copy
    must be the library's set, plus ``auto`` where the verb offers it."""
    from roft_sim.bags.messages import DEPTH_ENCODINGS, TWIST_LINEARS
    from roft_sim.metrics import INVALID_POLICIES

    sets = {"--invalid": INVALID_POLICIES, "--depth-encoding": DEPTH_ENCODINGS}
    sets["--twist-linear"] = TWIST_LINEARS
    seen = []
    for command, option, action in _options(build_parser()):
        if option in sets:
            seen.append((command, option))
            assert set(action.choices) - {"auto"} == set(sets[option]), (command, option)
    assert ("run", "--invalid") in seen and ("bag score", "--invalid") in seen
    assert ("bag export", "--depth-encoding") in seen and ("bag score", "--twist-linear") in seen
