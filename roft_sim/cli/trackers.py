"""``roft-sim trackers``: list the registered tracker plugins, or print one's default settings.

- ``roft-sim trackers``: one line per tracker (name, what it needs, description).
- ``roft-sim trackers --json``: the same as JSON (name, description, config type, needs a depth
  renderer, detection mode, entry point).
- ``roft-sim trackers --defaults NAME``: the tracker's default configuration as TOML, ready to
  edit and pass back as a config file.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from importlib.metadata import entry_points
from typing import Any

from roft_sim.config_files import jsonable, toml_value

__all__ = ["register", "toml_from_dataclass"]


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    parser = subparsers.add_parser(
        "trackers",
        help="list the registered tracker plugins",
        description="Lists the trackers registered under the entry-point group "
        "'roft_sim.trackers' (see docs/plugins.md).",
    )
    parser.add_argument("--json", action="store_true", help="print the list as JSON")
    parser.add_argument(
        "--defaults",
        metavar="NAME",
        help="print the default configuration of tracker NAME as TOML",
    )
    parser.set_defaults(func=_run)


def toml_from_dataclass(config: Any, table: str = "") -> str:
    """TOML text of a (nested) config dataclass: scalars and lists first, then sub-tables.

    Fields whose value is None are left out (TOML has no null; the default is None).
    """
    lines: list[str] = []
    nested: list[tuple[str, Any]] = []
    for f in dataclasses.fields(config):
        value = getattr(config, f.name)
        if dataclasses.is_dataclass(value):
            nested.append((f.name, value))
        elif value is not None:
            lines.append(f"{f.name} = {toml_value(value)}")
    text = ""
    if table:
        text += f"[{table}]\n"
    text += "".join(line + "\n" for line in lines)
    for name, value in nested:
        sub = f"{table}.{name}" if table else name
        text += "\n" + toml_from_dataclass(value, sub)
    return text


def _run(args: argparse.Namespace) -> int:
    from roft_sim.cli.run import resolve_tracker
    from roft_sim.trackers import ENTRY_POINT_GROUP, discover_trackers

    if args.defaults:
        spec, _ = resolve_tracker(args.defaults, None)  # unknown names: exit 2, as in run
        print(f"# default settings of tracker {spec.name!r} ({spec.config_type.__name__})")
        print(toml_from_dataclass(spec.config_type()), end="")
        return 0
    specs = discover_trackers()
    sources = {ep.name: ep.value for ep in entry_points(group=ENTRY_POINT_GROUP)}
    if args.json:
        rows = [
            {
                "name": spec.name,
                "description": spec.description,
                "config_type": f"{spec.config_type.__module__}.{spec.config_type.__qualname__}",
                "needs_depth_renderer": spec.needs_depth_renderer,
                "detection_mode": spec.detection_mode,
                "entry_point": sources.get(spec.name),
            }
            for spec in specs.values()
        ]
        print(json.dumps(jsonable(rows), indent=2))
        return 0
    if not specs:
        print(f"no trackers registered under the entry-point group {ENTRY_POINT_GROUP!r}")
        return 0
    width = max(len(name) for name in specs)
    for name, spec in specs.items():
        needs = []
        if spec.needs_depth_renderer:
            needs.append("depth renderer")
        if spec.detection_mode == "ideal":
            needs.append("ideal detections")
        tag = f"[{', '.join(needs)}] " if needs else ""
        print(f"{name:<{width}}  {tag}{spec.description}")
    return 0
