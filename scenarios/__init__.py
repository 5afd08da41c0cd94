"""Data package ``roft_sim.scenarios``: the shipped scenario files (``ci/``, ``fast_ycb/``) and
fault presets (``faults/``). It lives at ``scenarios/`` in the repository root and is installed
as ``roft_sim/scenarios/`` (``[tool.setuptools.package-dir]`` in pyproject.toml)."""
