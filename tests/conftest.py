"""Shared pytest set-up: the offline Menagerie model from ../shared and the repo root."""
import os
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[1]
SHARED_CASSIE = REPO_ROOT.parent / "shared" / "cassie"

# The models are data kept beside the repo (never copied in); point mujoco-menagerie at
# the offline copy unless the user has set it already.
os.environ.setdefault("MENAGERIE_ROOT", str(SHARED_CASSIE / "menagerie"))

import importlib.util
import sys

import pytest


def load_build_module():
    """build.py as a module (named avr_build: `import build` would clash with PyPA's build)."""
    spec = importlib.util.spec_from_file_location("avr_build", REPO_ROOT / "build.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("avr_build", module)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="session")
def build_module():
    return load_build_module()


@pytest.fixture(scope="session")
def built_fmu(tmp_path_factory, build_module):
    """The FMU exactly as build.py builds it, into a fresh temporary folder (once per session)."""
    return build_module.build_fmu(tmp_path_factory.mktemp("fmu"))
