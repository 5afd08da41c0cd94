"""The documentation is tested: its runnable command blocks run, and its size stays in budget.

Every fenced block whose info string is ``bash doc-test`` in README.md and docs/*.md is run. The
blocks of one Markdown file run in order in one ``bash -euo pipefail`` shell, in a fresh
temporary folder in which the repository's top-level folders are symlinked (so commands read as
from the repository root), with the venv's ``bin`` first on PATH, under a timeout. A failure
names the file and line of the block, shows the block and the tail of its output. Files run two
at a time (their shells are independent), each reported as its own test.

Blocks that need what a CI machine lacks (a GPU, real YCB meshes, long runs) are plain ``bash``.
"""

from __future__ import annotations

import concurrent.futures
import dataclasses
import importlib.util
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
LINKED_FOLDERS = ("scenarios", "examples", "benchmarks", "scripts", "assets", "docs")
"""Top-level folders the doc-test folder links to (HELPERS' convention)."""
TIMEOUT_S = 240
"""Per Markdown file; a shared 2-core machine under load needs the slack."""
README_MAX_LINES = 200
DOCS_MAX_LINES = 4000
_FENCE = re.compile(r"^```(?P<info>[^\n`]*)$")


@dataclasses.dataclass(frozen=True, slots=True)
class Block:
    """One ``bash doc-test`` block: where it is and its commands."""

    path: Path
    line: int
    """1-based line of the opening fence."""
    text: str


def markdown_files(root: Path = REPO) -> list[Path]:
    """README.md and docs/*.md."""
    return [root / "README.md", *sorted((root / "docs").glob("*.md"))]


def doc_test_blocks(path: Path) -> list[Block]:
    """The ``bash doc-test`` blocks of one Markdown file, in order."""
    blocks: list[Block] = []
    lines = path.read_text().splitlines()
    i = 0
    while i < len(lines):
        match = _FENCE.match(lines[i])
        if match is None:
            i += 1
            continue
        start, info = i, match.group("info").split()
        i += 1
        body: list[str] = []
        while i < len(lines) and not lines[i].startswith("```"):
            body.append(lines[i])
            i += 1
        if i == len(lines):
            raise AssertionError(f"{path}:{start + 1}: code block never closed")
        i += 1
        if info[:2] == ["bash", "doc-test"]:
            blocks.append(Block(path, start + 1, "\n".join(body)))
    return blocks


@dataclasses.dataclass(frozen=True, slots=True)
class FileRun:
    """What running one file's blocks gave."""

    returncode: int
    output: str
    failed_block: int | None
    """Index of the block that failed (the last one started), None when all passed."""
    seconds: float


def _script(blocks: list[Block]) -> str:
    parts = []
    for i, block in enumerate(blocks):
        parts.append(f"echo '@@doc-test-block {i}@@'\n{block.text}\n")
    return "".join(parts)


def run_blocks(blocks: list[Block], *, timeout_s: float = TIMEOUT_S) -> FileRun:
    """Runs the blocks in order in one ``bash -euo pipefail`` shell in a fresh folder."""
    venv_bin = Path(sys.executable).parent
    env = dict(os.environ)
    env["PATH"] = f"{venv_bin}{os.pathsep}{env.get('PATH', '')}"
    env.pop("PYTHONPATH", None)
    started = time.monotonic()
    with tempfile.TemporaryDirectory(prefix="roft-sim-doc-test-") as tmp:
        for name in LINKED_FOLDERS:
            (Path(tmp) / name).symlink_to(REPO / name)
        try:
            proc = subprocess.run(
                ["bash", "-euo", "pipefail", "-c", _script(blocks)],
                cwd=tmp,
                env=env,
                stdout=subprocess.PIPE,
                stderr=subprocess.STDOUT,
                stdin=subprocess.DEVNULL,
                text=True,
                timeout=timeout_s,
                check=False,
            )
            returncode, output = proc.returncode, proc.stdout
        except subprocess.TimeoutExpired as error:
            out = error.stdout
            text = out.decode(errors="replace") if isinstance(out, bytes) else (out or "")
            returncode, output = -1, text + f"\n[timed out after {timeout_s:.0f} s]"
    started_blocks = [int(m) for m in re.findall(r"@@doc-test-block (\d+)@@", output)]
    failed = None if returncode == 0 else (started_blocks[-1] if started_blocks else 0)
    return FileRun(returncode, output, failed, time.monotonic() - started)


def failure_message(blocks: list[Block], run: FileRun, *, tail_chars: int = 3000) -> str:
    """Where the failing block is, what it says, and the end of what it printed."""
    assert run.failed_block is not None
    block = blocks[run.failed_block]
    output = run.output.split(f"@@doc-test-block {run.failed_block}@@", 1)[-1]
    rel = block.path.relative_to(REPO) if block.path.is_relative_to(REPO) else block.path
    return (
        f"{rel}:{block.line}: doc-test block failed (exit {run.returncode})\n"
        f"--- block ---\n{block.text}\n--- output (tail) ---\n{output[-tail_chars:]}"
    )


_FILES_WITH_BLOCKS = [p for p in markdown_files() if doc_test_blocks(p)]


@pytest.fixture(scope="module")
def file_runs(request: pytest.FixtureRequest) -> dict[Path, concurrent.futures.Future[FileRun]]:
    """Starts every selected file's shell, two at a time, and hands out the futures."""
    selected = {
        item.callspec.params["path"]
        for item in request.session.items
        if item.module is sys.modules[__name__]
        and hasattr(item, "callspec")
        and "path" in item.callspec.params
    }
    pool = concurrent.futures.ThreadPoolExecutor(max_workers=2)
    request.addfinalizer(lambda: pool.shutdown(wait=True))
    return {
        path: pool.submit(run_blocks, doc_test_blocks(path))
        for path in _FILES_WITH_BLOCKS
        if path in selected
    }


@pytest.mark.render
@pytest.mark.parametrize(
    "path", _FILES_WITH_BLOCKS, ids=[str(p.relative_to(REPO)) for p in _FILES_WITH_BLOCKS]
)
def test_doc_test_blocks_run(
    path: Path, file_runs: dict[Path, concurrent.futures.Future[FileRun]]
) -> None:
    """Every ``bash doc-test`` block of the file runs without error, in order."""
    run = file_runs[path].result()
    if run.returncode != 0:
        pytest.fail(failure_message(doc_test_blocks(path), run), pytrace=False)


def test_a_failing_block_is_reported_with_its_file_line_and_output(tmp_path: Path) -> None:
    page = tmp_path / "page.md"
    page.write_text(
        "# Page\n\n```bash doc-test\necho first\n```\n\ntext\n\n"
        "```bash doc-test\necho 'about to fail'\nfalse\necho never\n```\n\n```bash\nnot run\n```\n"
    )
    blocks = doc_test_blocks(page)
    assert [b.line for b in blocks] == [3, 9]
    run = run_blocks(blocks, timeout_s=30)
    assert run.returncode != 0 and run.failed_block == 1
    message = failure_message(blocks, run)
    assert f"{page}:9:" in message and "false" in message and "about to fail" in message
    assert "never" not in message.split("--- output (tail) ---")[1]
    passing = run_blocks(blocks[:1], timeout_s=30)
    assert passing.returncode == 0 and passing.failed_block is None


def test_doc_test_blocks_see_the_repository_folders_and_the_venv(tmp_path: Path) -> None:
    page = tmp_path / "page.md"
    page.write_text(
        "```bash doc-test\ntest -f scenarios/ci/cracker_box.toml\n"
        f'test "$(command -v python)" = "{Path(sys.executable).parent}/python"\n```\n'
    )
    run = run_blocks(doc_test_blocks(page), timeout_s=30)
    assert run.returncode == 0, run.output


def test_every_page_has_an_unbroken_fence_structure() -> None:
    for path in markdown_files():
        doc_test_blocks(path)  # raises on an unclosed fence


def test_readme_and_docs_stay_in_their_line_budget() -> None:
    readme = len((REPO / "README.md").read_text().splitlines())
    assert readme <= README_MAX_LINES, f"README.md has {readme} lines (budget {README_MAX_LINES})"
    per_page = {p.name: len(p.read_text().splitlines()) for p in (REPO / "docs").rglob("*.md")}
    total = sum(per_page.values())
    assert total <= DOCS_MAX_LINES, f"docs/ has {total} lines (budget {DOCS_MAX_LINES}): {per_page}"


def test_no_development_history_in_readme_or_docs() -> None:
    """History lives in git log and CHANGELOG.md, not in the pages that describe the product."""
    pattern = re.compile(r"round [0-9]", re.IGNORECASE)
    hits = [
        f"{p.relative_to(REPO)}:{i}: {line.strip()}"
        for p in [REPO / "README.md", *sorted((REPO / "docs").rglob("*.md"))]
        for i, line in enumerate(p.read_text().splitlines(), 1)
        if pattern.search(line)
    ]
    assert not hits, "development rounds mentioned:\n" + "\n".join(hits[:20])


def _figures_module():  # type: ignore[no-untyped-def]
    spec = importlib.util.spec_from_file_location("docs_figures", REPO / "scripts/docs_figures.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules["docs_figures"] = module
    spec.loader.exec_module(module)
    return module


def test_every_figure_region_has_a_figure_that_makes_it_and_back() -> None:
    """scripts/refresh_docs_figures.sh can refresh every measured region the docs hold."""
    figures = _figures_module()
    regions = figures.find_regions(REPO)
    made = {r for f in figures.FIGURES for r in f.regions}
    assert set(regions) <= made, f"regions no figure makes: {set(regions) - made}"
    assert made <= set(regions), f"figures whose region is missing: {made - set(regions)}"
    assert all(len(paths) == 1 for paths in regions.values()), regions


def test_a_figure_region_is_rewritten_in_place() -> None:
    figures = _figures_module()
    text = (
        "a\n<!-- figure:x -->\nold\n<!-- /figure:x -->\n"
        "b\n<!-- figure:y -->\nkeep\n<!-- /figure:y -->\n"
    )
    new = figures.replace_region(text, "x", "new line")
    assert new == text.replace("old", "new line")
    with pytest.raises(ValueError, match="no region"):
        figures.replace_region(text, "z", "body")
