"""Where things are, for every test."""
from pathlib import Path

#: The checkout's root folder.
REPO_ROOT = Path(__file__).resolve().parents[2]
#: This folder: the shared helpers, the FMI drivers (``fmi/``) and the C hosts (``native/``).
SUPPORT_DIR = Path(__file__).resolve().parent
