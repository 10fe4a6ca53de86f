"""``python -m scenarios``: see :mod:`scenarios.cli`."""
import os
import sys

# Importing MuJoCo looks for an OpenGL library for its renderer (ctypes.util.find_library runs
# child processes: about 0.3 s of every start) unless MUJOCO_GL turns rendering off. Only
# `run --render` renders, and it picks a backend itself before MuJoCo is imported
# (scenarios.results.render.choose_gl_backend). A MUJOCO_GL already set is kept.
if "--render" not in sys.argv[1:]:
    os.environ.setdefault("MUJOCO_GL", "disable")

from scenarios.cli import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main())
