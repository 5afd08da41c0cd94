"""Regenerates the measured figures that README.md and docs/ include (run it through
``scripts/refresh_docs_figures.sh``).

Every figure runs real commands (``roft-sim`` verbs, ``benchmarks/*.py``) in a scratch folder in
which the repository's top-level folders are symlinked, and writes:

- the region between ``<!-- figure:NAME -->`` and ``<!-- /figure:NAME -->`` in the Markdown file
  that holds it (README.md or docs/*.md): a line saying which machine (CPU model, cores, load)
  made it, when, and in which mode, then the commands and what they printed (or a table made from
  their output files);
- pictures under docs/images/.

    python scripts/docs_figures.py --list
    python scripts/docs_figures.py --quick                  # every figure, small sizes
    python scripts/docs_figures.py demo sweep-delay         # these figures, full size
    python scripts/docs_figures.py --quick --keep work/ paper

Figures that need data the repository does not ship (real YCB meshes, captured motion) take it
from ``--assets`` / ``$ROFT_SIM_ASSETS`` and ``--trajectories`` / ``$ROFT_SIM_TRAJECTORIES`` (else
``../shared/ycb`` and ``../shared/trajectories`` beside the repository when present) and say in
their region what they used.
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import datetime
import os
import re
import shlex
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
"""The repository whose README.md and docs/ are refreshed."""

LINKED_FOLDERS = ("scenarios", "examples", "benchmarks", "scripts", "assets", "docs")
"""Top-level folders symlinked into the scratch folder, so commands read as from the root."""

MARKDOWN_GLOBS = ("README.md", "docs/*.md")
"""The files whose figure regions are rewritten."""

_REGION = re.compile(
    r"(?P<open><!-- figure:(?P<name>[a-z0-9-]+) -->\n)(?P<body>.*?)"
    r"(?P<close><!-- /figure:(?P=name) -->)",
    re.S,
)


@dataclasses.dataclass(frozen=True, slots=True, kw_only=True)
class Context:
    """What a figure needs to run."""

    quick: bool
    """Small sizes (minutes in all) instead of the full ones."""
    work: Path
    """Scratch folder (cwd of every command), with the repository's folders linked."""
    assets: Path | None
    """Real YCB meshes, when available."""
    trajectories: Path | None
    """Captured motion (TUM VI, CMU), when available."""
    workers: int
    """Worker processes for the verbs that take ``--workers``."""


@dataclasses.dataclass(frozen=True, slots=True, kw_only=True)
class Output:
    """What a figure produced: Markdown per region name, and the pictures it wrote."""

    regions: dict[str, str]
    images: tuple[Path, ...] = ()


@dataclasses.dataclass(frozen=True, slots=True, kw_only=True)
class Figure:
    """A figure: its name, what it shows, the regions it fills, and how it is made."""

    name: str
    description: str
    regions: tuple[str, ...]
    make: Callable[[Context], Output]


class CommandLog:
    """Runs commands in the scratch folder and keeps them with the tail of what they printed."""

    def __init__(self, context: Context) -> None:
        self.context = context
        self.entries: list[tuple[str, str]] = []

    def run(self, command: str, *, show_lines: int | None = 60, keep: bool = True) -> str:
        """Runs ``command`` (a shell line, ``roft-sim`` and ``python`` from the venv) and
        returns its standard output; stops the script with the output tail on failure."""
        env = dict(os.environ)
        env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
        print(f"[{time.strftime('%H:%M:%S')}] $ {command}", file=sys.stderr, flush=True)
        proc = subprocess.run(
            ["bash", "-euo", "pipefail", "-c", command],
            cwd=self.context.work,
            env=env,
            capture_output=True,
            text=True,
            check=False,
        )
        if proc.returncode != 0:
            tail = (proc.stdout + proc.stderr)[-4000:]
            raise SystemExit(f"figure command failed ({proc.returncode}): {command}\n{tail}")
        if keep:
            lines = proc.stdout.rstrip("\n").splitlines()
            if show_lines is not None and len(lines) > show_lines:
                lines = [*lines[:show_lines], f"... ({len(lines) - show_lines} more lines)"]
            self.entries.append((command, "\n".join(lines)))
        return proc.stdout

    def markdown(self) -> str:
        """The commands and their output as one ``text`` block."""
        parts = []
        for command, output in self.entries:
            parts.append(f"$ {command}")
            if output:
                parts.append(output)
        return "```text\n" + "\n".join(parts) + "\n```\n"


# ------------------------------------------------------------------------------- the machine
def machine_line(context: Context, figure: str) -> str:
    """The provenance line every region starts with."""
    cpu = "unknown CPU"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    mode = "--quick " if context.quick else ""
    size = "quick mode (small sizes)" if context.quick else "full size"
    date = datetime.date.today().isoformat()
    return (
        f"_Made by `bash scripts/refresh_docs_figures.sh {mode}{figure}` on {date}: {cpu}, "
        f"{os.cpu_count()} cores, load {load:.1f} at the start; {size}. Numbers vary with the "
        "machine and its load._\n"
    )


def _data_note(context: Context) -> str:
    meshes = "real YCB meshes" if context.assets else "procedural stand-ins of the YCB objects"
    return f"Objects: {meshes}.\n"


def _assets_flag(context: Context) -> str:
    return f" --assets {shlex.quote(str(context.assets))}" if context.assets else ""


# ------------------------------------------------------------------------------- figures
def make_demo(context: Context) -> Output:
    """``roft-sim demo`` (README's table) and README's picture from the same run."""
    log = CommandLog(context)
    size = " --frames 60 --resolution 320x180" if context.quick else ""
    log.run(f"roft-sim demo --out out/demo{size} --no-progress", show_lines=8)
    image = REPO / "docs" / "images" / "overview.png"
    overview_picture(context.work / "out" / "demo", image)
    return Output(regions={"demo": log.markdown()}, images=(image,))


def overview_picture(demo_dir: Path, out: Path) -> None:
    """One frame's rgb | depth | mask | flow above each tracker's position and rotation error
    over time, from a ``roft-sim demo`` folder."""
    import matplotlib

    matplotlib.use("Agg")
    import numpy as np
    from matplotlib.figure import Figure as MplFigure

    from roft_sim.datasets import list_sequences, open_sequence
    from roft_sim.render.preview import depth_to_rgb, flow_to_rgb

    sequence = open_sequence(list_sequences(demo_dir / "dataset")[0])
    n = len(sequence)
    flows = {k: sequence.flow(k, "gt") for k in range(1, n)}
    speed = {k: float(np.hypot(*f.flow_px.reshape(-1, 2).T).mean()) for k, f in flows.items() if f}
    k = max(speed, key=lambda i: speed[i] if i >= n // 3 else -1.0)
    flow = flows[k]
    assert flow is not None
    depth = sequence.depth(k)
    measured = depth[depth > 0]
    near, far = (float(np.percentile(measured, 1)), float(np.percentile(measured, 99)))
    mask = sequence.mask(k, "gt")
    mask_rgb = np.zeros(depth.shape + (3,), np.uint8)
    if mask is not None:
        mask_rgb[mask] = 255
    magnitude = np.hypot(flow.flow_px[..., 0], flow.flow_px[..., 1])
    moving = magnitude[magnitude > 0.05]
    flow_rgb = flow_to_rgb(flow, max(1.0, float(np.percentile(moving, 90))) if moving.size else 1.0)
    panels = [
        ("rgb", sequence.rgb(k)),
        ("depth", depth_to_rgb(depth, near, far)),
        ("object mask", mask_rgb),
        ("optical flow (hue: direction)", flow_rgb),
    ]
    height, width = depth.shape
    panel_h = 3.0 * height / width  # four 3-inch panels across a 12-inch figure
    figure = MplFigure(figsize=(12, panel_h + 3.6), dpi=100, layout="constrained")
    grid = figure.add_gridspec(2, 4, height_ratios=(panel_h, 2.8))
    for i, (title, image) in enumerate(panels):
        ax = figure.add_subplot(grid[0, i])
        ax.imshow(image, interpolation="nearest")
        ax.set_title(f"{title}, frame {k}", fontsize=9)
        ax.set_axis_off()
    ax_t = figure.add_subplot(grid[1, :2])
    ax_a = figure.add_subplot(grid[1, 2:])
    arrivals: set[int] = set()
    for run in sorted((demo_dir / "runs").iterdir()):
        errors = np.load(run / sequence.name / "frame_errors.npz")
        frames = errors["frame_index"]
        ax_t.plot(frames, np.linalg.norm(errors["t_err_cm"], axis=1), label=run.name)
        ax_a.plot(frames, errors["a_err_deg"], label=run.name)
        deliveries = np.load(run / sequence.name / "deliveries.npz")
        arrivals.update(int(a) for a in deliveries["pose"][:, 3])
    for ax, label in ((ax_t, "position error [cm]"), (ax_a, "rotation error [deg]")):
        for a in sorted(arrivals):
            ax.axvline(a, color="0.8", lw=0.8, ls="--", zorder=0)
        ax.set_xlabel("frame (grey: a delayed pose arrives)")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    ax_t.legend(fontsize=8)
    figure.suptitle(
        f"{sequence.name}: one frame of the data, and each tracker's error over time "
        "under the paper's delays",
        fontsize=10,
    )
    out.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(out)


def make_trajectory_speeds(context: Context) -> Output:
    """Speeds of the synthetic motion profiles (and of the captured motion when present)."""
    log = CommandLog(context)
    if context.trajectories is not None:  # the captured splits beside both profiles
        log.run(
            "roft-sim -q trajectory stats --hand-motion --trajectories "
            f"{shlex.quote(str(context.trajectories))}"
        )
    else:
        for profile in ("bursty", "continuous"):
            log.run(
                f"roft-sim -q trajectory stats --synthetic --profile {profile} --seed 0 "
                "--duration-s 30"
            )
    return Output(regions={"trajectory-speeds": log.markdown()})


def make_sweep_delay(context: Context) -> Output:
    """A sweep of the networks' delay: pivot table and the error-versus-delay plot."""
    log = CommandLog(context)
    objects = ("003_cracker_box", "005_tomato_soup_can", "006_mustard_bottle")
    if context.quick:
        objects, frames, resolution, delays = objects[:2], 60, "320x180", "0:12:4"
    else:
        frames, resolution, delays = 150, "640x360", "0:20:2"
    scenarios = " ".join(f"scenarios/fast_ycb/{o}.toml" for o in objects)
    log.run(
        f"roft-sim -q generate {scenarios} --out data --frames {frames} "
        f"--resolution {resolution} --workers {context.workers} --no-progress"
        f"{_assets_flag(context)}",
        show_lines=0,
    )
    log.run(
        "roft-sim -q sweep data --trackers roft,detector-hold,naive-delay,pose-only-ukf "
        f"--param delay={delays} --no-rgb --workers {context.workers} --out sweep "
        "--no-progress",
        show_lines=0,
    )
    rows = list(csv.DictReader((context.work / "sweep" / "summary.csv").open()))
    table = pivot_table(rows, "delay")
    image = REPO / "docs" / "images" / "sweep_error_vs_delay.png"
    shutil.copyfile(context.work / "sweep" / "plots" / "error_vs_delay.png", image)
    body = (
        log.markdown() + "\nADD-AUC % / e_t cm, ALL over the sequences "
        f"({len(objects)} x {frames} frames at {resolution}), per delay [frames]:\n\n"
        + table
        + "\n"
        + _data_note(context)
    )
    return Output(regions={"sweep-delay": body}, images=(image,))


def pivot_table(rows: Sequence[dict[str, str]], parameter: str) -> str:
    """Trackers x values of a sweep's swept parameter, from its summary.csv: ``ADD-AUC / e_t``
    of the ALL row (every frame of the cell's sequences pooled)."""
    value_key = parameter if parameter in rows[0] else "value"
    trackers: list[str] = []
    values: list[float] = []
    cells: dict[tuple[str, float], str] = {}
    for row in rows:
        tracker, value = row["tracker"], float(row[value_key])
        trackers += [tracker] if tracker not in trackers else []
        values += [value] if value not in values else []
        cells[tracker, value] = f"{float(row['add_auc_pct']):.1f} / {float(row['rmse_t_cm']):.2f}"
    values.sort()
    header = [f"{v:g}" for v in values]
    lines = ["| tracker | " + " | ".join(header) + " |", "|---" * (len(values) + 1) + "|"]
    for tracker in trackers:
        row_cells = " | ".join(cells.get((tracker, v), "") for v in values)
        lines.append(f"| {tracker} | {row_cells} |")
    return "\n".join(lines) + "\n"


def make_paper(context: Context) -> Output:
    """``roft-sim paper``: Table IV (ALL), the order of its rows, the paper's findings (for
    docs/paper.md) and the attribution table of ROFT's deviations (for docs/roft.md)."""
    log = CommandLog(context)
    size = "--resolution 320x180 --frames 60" if context.quick else ""
    log.run(
        f"roft-sim paper --out paper {size} --workers {context.workers} --no-plugins "
        f"--no-progress{_assets_flag(context)} > /dev/null",
        show_lines=0,
    )
    sections = markdown_sections((context.work / "paper" / "tables.md").read_text())
    table4 = _rows_not_containing(
        _section(sections, "Table IV: ablation"), "| ROFT (reference config) w"
    )
    order = _section(sections, "Table IV: order")
    taus = [
        re.sub(r"; paper best to worst.*", "", line)
        for line in order.splitlines()
        if line.startswith(("- ", "Configuration"))
    ]
    findings = [
        re.sub(r" \(\w+: .*$", "", line)
        for line in _section(sections, "The paper's findings").splitlines()
        if line.startswith(("- ", "Configuration"))
    ]
    shown = (
        log.markdown()
        + "\nTable IV (ALL over the six objects), simulated beside the published numbers:\n\n"
        + _drop_images(table4).rstrip("\n")
        + "\n"
        + "\nKendall's tau between the paper's and the simulated order of the nine ROFT rows:\n"
        + _markdown_lines(taus)
        + "\nThe paper's findings, checked:\n"
        + _markdown_lines(findings)
        + "\n"
        + _data_note(context)
    )
    attribution = (
        log.markdown()
        + "\n"
        + _drop_images(_section(sections, "Attribution"))
        + "\n"
        + _data_note(context)
    )
    return Output(regions={"paper": shown, "paper-attribution": attribution})


def _markdown_lines(lines: Sequence[str]) -> str:
    """``Configuration ...:`` headers and their ``- `` items, each header after a blank line."""
    return "".join(
        ("\n" + line + "\n\n") if line.startswith("Configuration") else line + "\n"
        for line in lines
    )


def markdown_sections(text: str) -> dict[str, str]:
    """``## `` heading -> the text under it (up to the next ``## `` heading)."""
    sections: dict[str, str] = {}
    for chunk in re.split(r"^## ", text, flags=re.M)[1:]:
        heading, _, body = chunk.partition("\n")
        sections[heading.strip()] = body.strip() + "\n"
    return sections


def _section(sections: dict[str, str], prefix: str) -> str:
    for heading, body in sections.items():
        if heading.startswith(prefix):
            return body
    raise SystemExit(f"tables.md has no section starting with {prefix!r}: {list(sections)}")


def _rows_not_containing(markdown: str, text: str) -> str:
    return "".join(line for line in markdown.splitlines(keepends=True) if text not in line)


def _drop_images(markdown: str) -> str:
    return re.sub(r"^!\[.*$\n?", "", markdown, flags=re.M)


def _bench(
    name: str, quick: str, full: str, region: str, show_lines: int | None = 60
) -> Callable[[Context], Output]:
    def make(context: Context) -> Output:
        log = CommandLog(context)
        args = quick if context.quick else full
        log.run(f"python benchmarks/{name} {args}".strip(), show_lines=show_lines)
        return Output(regions={region: log.markdown()})

    return make


def make_stress(context: Context) -> Output:
    """The stress benchmark's verdict lines and, per split, the default inputs' rows under the
    ``paper`` preset (``OUT/report.md`` has every table)."""
    log = CommandLog(context)
    size = "--quick" if context.quick else "--medium"
    traj = (
        f" --trajectories {shlex.quote(str(context.trajectories))}" if context.trajectories else ""
    )
    log.run(
        f"python benchmarks/bench_robustness.py {size} --out stress --workers "
        f"{context.workers} --no-per-sequence{traj} > /dev/null",
        show_lines=0,
    )
    report = (context.work / "stress" / "report.md").read_text()
    body = log.markdown() + "\n" + stress_summary(report)
    if context.trajectories is None:
        body += "Captured motion absent: the TUM and CMU sequences were skipped.\n"
    return Output(regions={"stress": body})


def stress_summary(report: str) -> str:
    """The verdict lines and the ``paper`` rows of each split's default-inputs table."""
    lines = report.splitlines()
    out = [
        "| split | tracker | ADD-AUC % | e_t cm | e_a deg | e_v cm/s | e_w deg/s |",
        "|---" * 7 + "|",
    ]
    split = None
    for i, line in enumerate(lines):
        if line.startswith("### ") and "default inputs" in line:
            split = line[4:].split(":")[0]
        elif line.startswith("### "):
            split = None
        elif split and line.startswith("| paper |"):
            cells = [c.strip() for c in line.strip("|").split("|")]
            out.append(f"| {split} | " + " | ".join(cells[1:7]) + " |")
        del i
    start = next(i for i, line in enumerate(lines) if line.startswith("## Verdict"))
    verdicts = [line for line in lines[start + 1 :] if line and not line.startswith("#")]
    verdicts = [line for line in verdicts if ":" in line and "roft beats" in line]
    return (
        "Default inputs (the stored NVOF-like flow), `paper` preset, pooled over each split's "
        "sequences:\n\n"
        + "\n".join(out)
        + "\n\nVerdict lines:\n\n```text\n"
        + "\n".join(verdicts)
        + "\n```\n"
    )


FIGURES: tuple[Figure, ...] = (
    Figure(
        name="demo",
        description="roft-sim demo's table and README's picture",
        regions=("demo",),
        make=make_demo,
    ),
    Figure(
        name="trajectory-speeds",
        description="speed statistics of the motion profiles",
        regions=("trajectory-speeds",),
        make=make_trajectory_speeds,
    ),
    Figure(
        name="sweep-delay",
        description="trackers against the networks' delay",
        regions=("sweep-delay",),
        make=make_sweep_delay,
    ),
    Figure(
        name="paper",
        description="roft-sim paper's tables beside the published numbers",
        regions=("paper", "paper-attribution"),
        make=make_paper,
    ),
    Figure(
        name="stress",
        description="the stress benchmark's verdicts",
        regions=("stress",),
        make=make_stress,
    ),
    Figure(
        name="render",
        description="renderer throughput",
        regions=("render",),
        make=_bench("bench_render.py", "--frames 10 --repeats 2 --sizes 640x480", "", "render"),
    ),
    Figure(
        name="generate",
        description="generation throughput and memory",
        regions=("generate",),
        make=_bench(
            "bench_generate.py",
            "--resolutions 640x480 --workers 1 2 --repeats 1 --skip-memory",
            "--resolutions 640x480 1280x720 --workers 1 2 --repeats 2 --long-frames 600",
            "generate",
        ),
    ),
    Figure(
        name="png",
        description="PNG encoders",
        regions=("png",),
        make=_bench("bench_png.py", "--frames 4 --repeats 3", "", "png"),
    ),
    Figure(
        name="roft-step",
        description="ROFT's step time, default and reference configuration, stage by stage",
        regions=("roft-step",),
        make=_bench(
            "bench_roft.py",
            "--frames 60 --repeats 1 --resolutions 640x480 --config default reference",
            "--config default reference",
            "roft-step",
            show_lines=10,
        ),
    ),
)
"""Every figure, in the order a full refresh makes them."""


# ------------------------------------------------------------------------------- regions
def markdown_files(root: Path = REPO) -> list[Path]:
    """README.md and docs/*.md."""
    return sorted(p for pattern in MARKDOWN_GLOBS for p in root.glob(pattern))


def find_regions(root: Path = REPO) -> dict[str, list[Path]]:
    """Region name -> the Markdown files that hold a region of that name."""
    found: dict[str, list[Path]] = {}
    for path in markdown_files(root):
        text = path.read_text()
        for match in _REGION.finditer(text):
            found.setdefault(match.group("name"), []).append(path)
        opened = re.findall(r"<!-- figure:([a-z0-9-]+) -->", text)
        closed = re.findall(r"<!-- /figure:([a-z0-9-]+) -->", text)
        if sorted(opened) != sorted(closed):
            raise SystemExit(f"{path}: unbalanced figure markers: {opened} / {closed}")
    return found


def replace_region(text: str, name: str, body: str) -> str:
    """``text`` with the region ``name`` holding ``body``; ValueError when it has none."""
    if not any(m.group("name") == name for m in _REGION.finditer(text)):
        raise ValueError(f"no region <!-- figure:{name} --> in the text")
    if not body.endswith("\n"):
        body += "\n"
    return _REGION.sub(
        lambda m: (
            m.group("open") + body + m.group("close") if m.group("name") == name else m.group(0)
        ),
        text,
    )


def write_region(name: str, body: str, root: Path = REPO) -> Path:
    """Writes ``body`` into the one region ``name`` of README.md / docs/*.md."""
    paths = find_regions(root).get(name, [])
    if len(paths) != 1:
        raise SystemExit(f"region '{name}' must occur in exactly one file, found in {paths}")
    path = paths[0]
    path.write_text(replace_region(path.read_text(), name, body))
    return path


# ------------------------------------------------------------------------------- main
def _default_data(flag: Path | None, env: str, shared: str) -> Path | None:
    if flag is not None:
        return flag.resolve()
    if os.environ.get(env):
        return Path(os.environ[env]).resolve()
    candidate = REPO.parent / "shared" / shared
    return candidate if candidate.is_dir() else None


def _link_repository(work: Path) -> None:
    for name in LINKED_FOLDERS:
        link = work / name
        if not link.exists():
            link.symlink_to(REPO / name)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0] if __doc__ else None)
    parser.add_argument("figures", nargs="*", help="figure names (default: all); see --list")
    parser.add_argument("--quick", action="store_true", help="small sizes (minutes in all)")
    parser.add_argument("--list", action="store_true", help="list the figures and exit")
    parser.add_argument("--keep", type=Path, help="scratch folder to keep (default: a temp one)")
    parser.add_argument("--assets", type=Path, help="real YCB meshes (default: $ROFT_SIM_ASSETS)")
    parser.add_argument("--trajectories", type=Path, help="captured motion folder")
    parser.add_argument("--workers", type=int, default=2, help="worker processes (default 2)")
    args = parser.parse_args(argv)
    names = {f.name: f for f in FIGURES}
    if args.list:
        for figure in FIGURES:
            print(f"{figure.name:18s} {figure.description}")
        return 0
    unknown = [n for n in args.figures if n not in names]
    if unknown:
        parser.error(f"unknown figure(s) {unknown}; known: {', '.join(names)}")
    chosen = [names[n] for n in args.figures] if args.figures else list(FIGURES)
    regions = find_regions()
    for figure in chosen:
        for region in figure.regions:
            if len(regions.get(region, [])) != 1:
                raise SystemExit(
                    f"figure '{figure.name}': region '{region}' must occur in exactly "
                    f"one of README.md, docs/*.md; found {regions.get(region, [])}"
                )
    scratch = args.keep or Path(tempfile.mkdtemp(prefix="roft-sim-figures-"))
    try:
        for figure in chosen:
            work = scratch / figure.name
            if work.exists():
                shutil.rmtree(work)
            work.mkdir(parents=True)
            _link_repository(work)
            context = Context(
                quick=args.quick,
                work=work,
                assets=_default_data(args.assets, "ROFT_SIM_ASSETS", "ycb"),
                trajectories=_default_data(
                    args.trajectories, "ROFT_SIM_TRAJECTORIES", "trajectories"
                ),
                workers=args.workers,
            )
            header = machine_line(context, figure.name)
            started = time.monotonic()
            output = figure.make(context)
            for region, body in output.regions.items():
                path = write_region(region, header + "\n" + body)
                print(
                    f"{figure.name}: region '{region}' of {path.relative_to(REPO)} "
                    f"({time.monotonic() - started:.0f} s)",
                    file=sys.stderr,
                )
            for image in output.images:
                print(f"{figure.name}: {image.relative_to(REPO)}", file=sys.stderr)
    finally:
        if args.keep is None:
            shutil.rmtree(scratch, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
