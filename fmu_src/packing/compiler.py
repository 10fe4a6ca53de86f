"""The C compilers the build runs, all found by one rule: by name on ``PATH`` (the host's
compiler may be named by ``$CC``).

* the host's ``cc`` (or ``$CC``, else ``gcc``): the FMI guard and the native FMUs' Linux
  x86-64 libraries; the build cannot go on without it;
* the cross compilers in ``CROSS_COMPILERS`` (MinGW-w64 for win64, GCC for aarch64-linux):
  a platform whose cross compiler is missing is skipped, with a warning naming the Debian
  package that adds it (:func:`cross_compiler` returns None).
"""
from __future__ import annotations

import os
import shutil
import subprocess
from dataclasses import dataclass
from pathlib import Path

@dataclass(frozen=True)
class CrossCompiler:
    name: str  # the executable looked up on PATH
    package: str  # the Debian package that installs it
    platform: str  # what its binaries run on, for messages


#: Compiler target -> its cross compiler (the target "linux" is the host's compiler).
CROSS_COMPILERS = {
    "windows": CrossCompiler("x86_64-w64-mingw32-gcc", "gcc-mingw-w64-x86-64", "Windows x86-64"),
    "linux-aarch64": CrossCompiler("aarch64-linux-gnu-gcc", "gcc-aarch64-linux-gnu", "Linux aarch64"),
}


def host_compiler(purpose: str) -> str:
    """The path of ``$CC`` (default ``cc``, else ``gcc``); RuntimeError naming ``purpose`` if none."""
    compiler = shutil.which(os.environ.get("CC", "cc")) or shutil.which("gcc")
    if compiler is None:
        raise RuntimeError(f"build.py needs a C compiler (cc or gcc; set CC) {purpose}")
    return compiler


def cross_compiler(target: str) -> str | None:
    """The path of the cross compiler for ``target`` (a key of ``CROSS_COMPILERS``), None if it is not installed."""
    return shutil.which(CROSS_COMPILERS[target].name)


def compiler_for(target: str, purpose: str) -> str:
    """The compiler for ``target`` ("linux": the host's; else a cross compiler); RuntimeError
    naming the Debian package if it is missing."""
    if target == "linux":
        return host_compiler(purpose)
    path = cross_compiler(target)
    if path is None:
        cross = CROSS_COMPILERS[target]
        raise RuntimeError(f"build.py needs the cross compiler {cross.name} for the {cross.platform} binaries "
                           f"{purpose} (Debian: apt-get install {cross.package})")
    return path


def skip_message(target: str, what: str) -> str:
    """The warning for a platform skipped because its cross compiler is missing."""
    cross = CROSS_COMPILERS[target]
    return (f"skipped the {cross.platform} binaries of {what}: the cross compiler {cross.name} is not on PATH "
            f"(Debian: apt-get install {cross.package})")


def run(cmd: list[str], what: str, cwd: Path | None = None) -> None:
    """Run the compiler command ``cmd``; RuntimeError with the command and its messages if it fails."""
    result = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True)
    if result.returncode != 0:
        raise RuntimeError(f"compiling {what} failed:\n{' '.join(cmd)}\n{result.stderr}")
