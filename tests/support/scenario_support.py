"""Shared by the CLI tests: a small valid scenario file."""
from __future__ import annotations

from pathlib import Path

# 0.5 s of standing is enough for every arm to complete and for every file to be written.
QUICK_S = 0.5


def scenario_file(folder: Path, name: str, *, duration_s: float = QUICK_S, arms=("adaptive",), file=None,
                  model: str | None = None) -> Path:
    path = folder / (file or f"{name}.toml")
    compare = ", ".join(f'"{a}"' for a in arms)
    model_line = f'model = "{model}"\n' if model else ""
    path.write_text(f'''name = "{name}"
description = "a test scenario"
duration_s = {duration_s}
seed = 1
{model_line}compare = [{compare}]
[[command]]
t_s = 0.0
vx_des = 0.5
[claim]
text = "it stands"
[[claim.check]]
arm = "adaptive"
metric = "fell"
op = "=="
value = false
''')
    return path
