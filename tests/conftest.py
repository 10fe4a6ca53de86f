"""Shared pytest set-up: the offline Menagerie model from ../shared and the repo root."""
import os
from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]
SHARED_CASSIE = REPO_ROOT.parent / "shared" / "cassie"

# The models are data kept beside the repo (never copied in); point mujoco-menagerie at
# the offline copy unless the user has set it already.
os.environ.setdefault("MENAGERIE_ROOT", str(SHARED_CASSIE / "menagerie"))


@pytest.fixture(scope="session")
def build_module():
    """build.py as a module (the CLI's loader: `import build` would clash with PyPA's build)."""
    from scenarios.cli import load_build_module

    return load_build_module()


@pytest.fixture(scope="session")
def built_fmu(tmp_path_factory, build_module):
    """The FMU exactly as build.py builds it, into a fresh temporary folder (once per session)."""
    return build_module.build_fmu(tmp_path_factory.mktemp("fmu"))
