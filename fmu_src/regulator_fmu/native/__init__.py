"""The regulator in C: the native FMI 2.0 / 3.0 FMUs' sources and their generators (header.py, describe.py)."""
