"""``run --render``: each arm's MP4 and GIF from the tracking camera, headless (scenarios.results.render)."""
from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import imageio.v2 as imageio
import imageio_ffmpeg
import numpy as np

from scenarios import cli
from scenarios.results import output, render
from support.paths import REPO_ROOT

#: A frame showing the scene (the checkered floor, the sky, the robot) has a pixel standard
#: deviation of ~30 (measured 28-31 over the nominal run); a blank frame (only the clear
#: colour, or a failed read-back) has ~0. 10 tells them apart with a wide margin.
MIN_FRAME_STD = 10.0
#: Mean absolute pixel difference between the first and the last frame of the 2 s walk:
#: measured ~6.7 (the legs swing, the floor slides under the tracking camera). Two renders
#: of one pose differ only by the H.264 compression noise, measured below ~0.3 between
#: consecutive frames; 2.0 needs real motion.
MIN_MOTION = 2.0


def _env(tmp_path: Path) -> dict[str, str]:
    systemp = tmp_path / "systemp"  # stands for the system temp folder: must stay empty
    systemp.mkdir(exist_ok=True)
    return {**os.environ, "TMPDIR": str(systemp)}


def _check_frames(frames: np.ndarray, shape: tuple[int, int, int]) -> None:
    assert frames.shape[1:] == shape
    stds = frames.reshape(len(frames), -1).std(axis=1)
    assert stds.min() > MIN_FRAME_STD, stds.min()
    motion = np.abs(frames[-1].astype(float) - frames[0].astype(float)).mean()
    assert motion > MIN_MOTION, motion


def test_render_nominal_2s_writes_mp4_and_gif(tmp_path):
    # ffmpeg comes from imageio-ffmpeg's wheel, never from PATH
    assert Path(imageio_ffmpeg.get_ffmpeg_exe()).is_relative_to(Path(imageio_ffmpeg.__file__).parent)
    out = tmp_path / "runs"
    r = subprocess.run([sys.executable, "-m", "scenarios", "run", "nominal", "--duration", "2", "--render",
                        "--regulator", "inprocess", "--no-plots", "--out", str(out)],
                       capture_output=True, text=True, timeout=600, cwd=REPO_ROOT, env=_env(tmp_path))
    assert r.returncode == 0, r.stderr
    folder = out / "nominal"
    summary = json.loads((folder / "summary.json").read_text())
    assert summary["videos"] == ["adaptive.mp4", "adaptive.gif", "pd_only.mp4", "pd_only.gif"]
    assert summary["timings"]["videos_s"] > 0
    assert output.summary_problems(summary) == []
    # a frame every 7 communication steps of 5 ms (1/30 s rounded to whole steps): 400 steps -> 58 frames
    every = round(1 / (render.FPS * 0.005))
    for arm in ("adaptive", "pd_only"):
        mp4 = imageio.get_reader(folder / f"{arm}.mp4")
        assert math.isclose(mp4.get_meta_data()["fps"], 1 / (every * 0.005), rel_tol=1e-3)
        frames = np.array([f for f in mp4])
        mp4.close()
        assert len(frames) == math.ceil(400 / every)
        _check_frames(frames, (render.VIDEO_SIZE[1], render.VIDEO_SIZE[0], 3))
        gif = np.array(imageio.mimread(folder / f"{arm}.gif"))[..., :3]
        # the whole 2 s run (shorter than GIF_SECONDS) at every 3rd frame (~9.5 fps)
        assert len(gif) == math.ceil(len(frames) / round(1 / (every * 0.005) / render.GIF_FPS))
        _check_frames(gif, (render.GIF_SIZE[1], render.GIF_SIZE[0], 3))
    r = subprocess.run([sys.executable, "-m", "scenarios", "report", str(out)], capture_output=True, text=True,
                       timeout=120, cwd=REPO_ROOT, env=_env(tmp_path))
    assert r.returncode == 0, r.stderr
    report = (out / "report.md").read_text()
    assert "Videos: [adaptive.mp4](nominal/adaptive.mp4), [pd_only.mp4](nominal/pd_only.mp4)" in report
    assert "![nominal adaptive.gif](nominal/adaptive.gif)" in report
    assert list((tmp_path / "systemp").iterdir()) == []


def test_render_refuses_plant_fmu_and_a_backend_that_cannot_render(tmp_path, monkeypatch, capsys):
    """Both problems at once, each naming its fix; nothing simulated, nothing written."""
    monkeypatch.setenv("MUJOCO_GL", "nonsense")  # MuJoCo refuses it at import (in the probing child)
    out = tmp_path / "runs"
    rc = cli.main(["run", "nominal", "--render", "--plant", "fmu", "--out", str(out)])
    err = capsys.readouterr().err
    assert rc == 2
    assert "--render with --plant fmu: the CassiePlant FMU gives no MuJoCo state to render" in err
    assert "MUJOCO_GL=nonsense" in err and "unset MUJOCO_GL or set it to egl or osmesa" in err
    assert not out.exists()


def test_results_folder_accepts_the_arms_videos_only():
    assert output.is_result_file("adaptive.mp4") and output.is_result_file("pd_only.gif")
    assert output.is_result_file("velocity.png")
    for name in ("adaptive.avi", "Adaptive.mp4", ".mp4", "../x.gif", "a/b.mp4", "notes.txt"):
        assert not output.is_result_file(name), name


#: Runs ``python -m scenarios`` with the given arguments (``--help``: it stops after parsing), then
#: imports MuJoCo as the command would, and prints MUJOCO_GL and whether MuJoCo's GLFW renderer
#: was imported.
_GL_PROBE = ("import os, runpy, sys\n"
             "try:\n    runpy.run_module('scenarios', run_name='__main__', alter_sys=True)\n"
             "except SystemExit:\n    pass\n"
             "import mujoco\n"
             "print(os.environ.get('MUJOCO_GL'), 'glfw' in sys.modules)")


def _gl_probe(*args: str) -> list[str]:
    env = {k: v for k, v in os.environ.items() if k != "MUJOCO_GL"}
    done = subprocess.run([sys.executable, "-c", _GL_PROBE, *args], env=env, capture_output=True, text=True,
                          cwd=REPO_ROOT, timeout=120)
    assert done.returncode == 0, done.stderr
    return done.stdout.split()[-2:]


def test_the_cli_skips_mujocos_opengl_search_unless_it_renders():
    """``python -m scenarios`` sets MUJOCO_GL=disable (MuJoCo then skips its OpenGL search, about
    0.3 s of every start) unless it renders: ``run --render`` chooses its own backend."""
    assert _gl_probe("run", "--help") == ["disable", "False"]
    assert _gl_probe("run", "--render", "--help") == ["None", "True"]
