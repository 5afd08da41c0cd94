"""Data package ``roft_sim.scenarios``: the shipped scenario files (``ci/``, ``fast_ycb/``), fault
presets (``faults/``), stress-benchmark files (``sweeps/``) and tracker configurations
(``trackers/``). It lives at ``scenarios/`` in the repository root and is installed
as ``roft_sim/scenarios/`` (``[tool.setuptools.package-dir]`` in pyproject.toml)."""
