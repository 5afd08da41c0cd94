"""Data package holding ``manifest.toml``, the registry of YCB objects."""
