"""Shared pytest set-up: the offline Menagerie model from ../shared and the repo root."""
import os
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[1]
SHARED_CASSIE = REPO_ROOT.parent / "shared" / "cassie"

# The models are data kept beside the repo (never copied in); point mujoco-menagerie at
# the offline copy unless the user has set it already.
os.environ.setdefault("MENAGERIE_ROOT", str(SHARED_CASSIE / "menagerie"))
