"""The C compilers the build runs: the host's ``cc`` (or ``$CC``) and MinGW-w64 for win64."""
from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

MINGW_CC = "x86_64-w64-mingw32-gcc"  # Debian package gcc-mingw-w64-x86-64


def host_compiler(purpose: str) -> str:
    """The path of ``$CC`` (default ``cc``, else ``gcc``); RuntimeError naming ``purpose`` if none."""
    compiler = shutil.which(os.environ.get("CC", "cc")) or shutil.which("gcc")
    if compiler is None:
        raise RuntimeError(f"build.py needs a C compiler (cc or gcc; set CC) {purpose}")
    return compiler


def mingw_compiler() -> str:
    compiler = shutil.which(MINGW_CC)
    if compiler is None:
        raise RuntimeError(f"build.py needs the MinGW-w64 cross compiler {MINGW_CC} for the win64 binaries "
                           "(Debian: apt-get install gcc-mingw-w64-x86-64)")
    return compiler


def run(cmd: list[str], what: str, cwd: Path | None = None) -> None:
    """Run the compiler command ``cmd``; RuntimeError with the command and its messages if it fails."""
    result = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True)
    if result.returncode != 0:
        raise RuntimeError(f"compiling {what} failed:\n{' '.join(cmd)}\n{result.stderr}")
