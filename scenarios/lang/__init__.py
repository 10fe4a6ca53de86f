"""The scenario file language: TOML scenario files -> validated frozen dataclasses (every problem at once)."""
