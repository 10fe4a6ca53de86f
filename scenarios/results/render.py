"""``run --render``: a video of each arm from a camera that follows the pelvis.

Two halves, kept apart from the plant and from the master's loop logic:

- :class:`StateRecorder`, which the master loop calls every communication step; it
  decides when a frame is due (every ``n`` steps, ``n * h`` closest to 1/:data:`FPS`)
  and keeps only the plant's ``qpos`` then: a few kB per simulated second, cheap to
  send back from a worker process. The result is a :class:`StateTrack`.
- :func:`write_videos`, called by the results writer into the staged scenario folder
  (published with the rest, :mod:`scenarios.results.store`): it poses the scenario's compiled
  model at every recorded state, renders it offscreen (``mujoco.Renderer``) and writes
  ``<arm>.mp4`` (:data:`VIDEO_SIZE`, real time) and ``<arm>.gif`` (:data:`GIF_SIZE`,
  the last :data:`GIF_SECONDS` s at about :data:`GIF_FPS`).

Rendering needs a headless OpenGL: :func:`choose_gl_backend` picks ``MUJOCO_GL``
(``egl``, else ``osmesa``; a value already in the environment is kept) by trying each in
a child process, and must run before ``mujoco`` is imported in this process (MuJoCo
reads ``MUJOCO_GL`` once, at import); the spawned workers inherit the environment.
"""
from __future__ import annotations

import copy
import logging
import os
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import numpy as np

log = logging.getLogger(__name__)

#: Video frame rate aimed at (the frame interval is a whole number of communication steps).
FPS = 30.0
#: MP4 frame (width, height): fits MuJoCo's default offscreen buffer (640 x 480); both
#: multiples of 16, as H.264 wants.
VIDEO_SIZE = (640, 480)
#: The GIF: every MP4 frame downscaled 2 x 2, about this many frames per second ...
GIF_SIZE = (320, 240)
GIF_FPS = 10.0
#: ... over the last this many simulated seconds of the arm (the end: adapted or fallen).
GIF_SECONDS = 8.0
GIF_COLORS = 64
#: Tracking camera: distance (m), azimuth (deg; 90 looks at the robot's left side as it
#: walks along +x), elevation (deg).
CAMERA = (3.0, 90.0, -12.0)
#: The geom groups drawn: 0 (the floor, the terrain) and 3 (Cassie's collision shapes, what
#: the physics sees). Menagerie's visual meshes (group 2) are left out: MuJoCo 4.0 draws
#: them away from their bodies (legs beside the robot).
SHOWN_GEOM_GROUPS = (0, 3)
GL_BACKENDS = ("egl", "osmesa")
VIDEO_SUFFIXES = (".mp4", ".gif")

_PROBE = ("import mujoco; m = mujoco.MjModel.from_xml_string('<mujoco><worldbody><geom size=\".1\"/>"
          "</worldbody></mujoco>'); r = mujoco.Renderer(m, 16, 16); r.update_scene(mujoco.MjData(m)); r.render()")


# --------------------------------------------------------------------------- the GL backend
def _probe(backend: str) -> str | None:
    """None when MuJoCo renders with ``MUJOCO_GL=backend`` in a child process, else why not."""
    env = {**os.environ, "MUJOCO_GL": backend}
    env.pop("PYOPENGL_PLATFORM", None)  # MuJoCo sets it to match the backend
    try:
        done = subprocess.run([sys.executable, "-c", _PROBE], env=env, capture_output=True, text=True, timeout=60)
    except (OSError, subprocess.TimeoutExpired) as exc:
        return str(exc)
    if done.returncode == 0:
        return None
    lines = [ln for ln in done.stderr.strip().splitlines() if ln.strip()]
    return lines[-1] if lines else f"exit status {done.returncode}"


def choose_gl_backend() -> list[str]:
    """Set ``MUJOCO_GL`` to a headless backend that works here; the problems ([] when one does)."""
    given = os.environ.get("MUJOCO_GL")
    if "mujoco" in sys.modules and not given:
        return ["--render: mujoco was imported before the GL backend was chosen; set MUJOCO_GL=egl "
                "(or osmesa) in the environment before starting Python"]
    tried = []
    for backend in ([given] if given else GL_BACKENDS):
        why = _probe(backend)
        if why is None:
            os.environ["MUJOCO_GL"] = backend
            log.info("rendering with MUJOCO_GL=%s", backend)
            return []
        tried.append(f"MUJOCO_GL={backend}: {why}")
    fix = ("unset MUJOCO_GL or set it to egl or osmesa" if given else
           "install a headless OpenGL, e.g. `apt-get install libegl1` (EGL) or `apt-get install libosmesa6` (OSMesa)")
    return [f"--render: MuJoCo cannot render offscreen here ({'; '.join(tried)}); {fix}"]


# --------------------------------------------------------------------------- recording
@dataclass(frozen=True, eq=False)
class StateTrack:
    """The plant states to render: ``t`` (s, shape (F,)), ``qpos`` (F, nq), ``fps``."""

    t: np.ndarray
    qpos: np.ndarray
    fps: float


class StateRecorder:
    """Called with ``(k, t, walker)`` at every communication step ``k`` of length ``h``;
    keeps ``walker.data.qpos`` every ``every`` steps (``every * h`` closest to 1/``fps``)."""

    def __init__(self, h: float, fps: float = FPS) -> None:
        self.every = max(1, round(1.0 / (fps * h)))
        self.fps = 1.0 / (self.every * h)
        self.t: list[float] = []
        self.qpos: list[np.ndarray] = []

    def __call__(self, k: int, t: float, walker: Any) -> None:
        if k % self.every == 0:
            self.t.append(t)
            self.qpos.append(np.array(walker.data.qpos))

    def track(self) -> StateTrack:
        nq = self.qpos[0].shape[0] if self.qpos else 0
        return StateTrack(np.array(self.t), np.array(self.qpos).reshape(len(self.t), nq), self.fps)


# --------------------------------------------------------------------------- rendering
def _camera(model: Any) -> Any:
    import mujoco

    from plant.constants import PELVIS_BODY

    cam = mujoco.MjvCamera()
    cam.type = mujoco.mjtCamera.mjCAMERA_TRACKING
    cam.trackbodyid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, PELVIS_BODY)
    cam.distance, cam.azimuth, cam.elevation = CAMERA
    return cam


def _frames(model: Any, track: StateTrack):
    """Every recorded state rendered: (VIDEO_SIZE[1], VIDEO_SIZE[0], 3) uint8 arrays."""
    import mujoco

    model = copy.deepcopy(model)  # the shared compiled model is only read
    model.vis.quality.offsamples = 0  # no multisampling: it doubles a frame's cost on llvmpipe
    data = mujoco.MjData(model)
    cam = _camera(model)
    option = mujoco.MjvOption()
    option.geomgroup[:] = 0
    for group in SHOWN_GEOM_GROUPS:
        option.geomgroup[group] = 1
    width, height = VIDEO_SIZE
    with mujoco.Renderer(model, height, width) as renderer:
        for flag in (mujoco.mjtRndFlag.mjRND_SHADOW, mujoco.mjtRndFlag.mjRND_REFLECTION):
            renderer.scene.flags[flag] = False  # each ~10x a frame's cost on a software GL (llvmpipe)
        for qpos in track.qpos:
            data.qpos[:] = qpos
            mujoco.mj_forward(model, data)
            renderer.update_scene(data, cam, option)
            yield renderer.render()


def _half(frame: np.ndarray) -> np.ndarray:
    """``frame`` downscaled 2 x 2 (each pixel the mean of four)."""
    h, w = frame.shape[0] // 2 * 2, frame.shape[1] // 2 * 2
    f = frame[:h, :w].astype(np.uint16)
    return ((f[0::2, 0::2] + f[1::2, 0::2] + f[0::2, 1::2] + f[1::2, 1::2] + 2) // 4).astype(np.uint8)


def _write_gif(path: Path, frames: list[np.ndarray], frame_ms: float) -> None:
    """``frames`` as a looping GIF, all on the first frame's palette of :data:`GIF_COLORS`
    colours, undithered (dithering noise defeats the GIF's compression)."""
    from PIL import Image

    first = Image.fromarray(frames[0]).quantize(GIF_COLORS, dither=Image.Dither.NONE)
    rest = [Image.fromarray(f).quantize(palette=first, dither=Image.Dither.NONE) for f in frames[1:]]
    first.save(path, save_all=True, append_images=rest, duration=round(frame_ms), loop=0, optimize=False)


def write_arm_video(dest: Path, arm: str, model: Any, track: StateTrack) -> list[str]:
    """``dest/<arm>.mp4`` and ``dest/<arm>.gif`` of ``track``; their file names."""
    import imageio.v2 as imageio

    gif_every = max(1, round(track.fps / GIF_FPS))
    gif_from = len(track.t) - int(round(GIF_SECONDS * track.fps))
    gif = []
    with imageio.get_writer(dest / f"{arm}.mp4", format="FFMPEG", fps=track.fps, codec="libx264",
                            quality=6, macro_block_size=16, ffmpeg_log_level="error") as mp4:
        for i, frame in enumerate(_frames(model, track)):
            mp4.append_data(frame)
            if i >= gif_from and (i - max(gif_from, 0)) % gif_every == 0:
                gif.append(_half(frame))
    if gif:
        _write_gif(dest / f"{arm}.gif", gif, 1000.0 * gif_every / track.fps)
    return [f"{arm}.mp4"] + ([f"{arm}.gif"] if gif else [])


def write_videos(dest: Path, scenario: Any, results: Sequence[Any]) -> tuple[list[str], float]:
    """The videos of every result with a state track into ``dest``; their file names and
    the seconds it took."""
    from scenarios.lang.plantio import load_plant_model

    lap = time.perf_counter()
    tracked = [r for r in results if getattr(r, "track", None) is not None and len(r.track.t)]
    if not tracked:
        return [], 0.0
    model, _ = load_plant_model(scenario, shared=True)
    names = []
    for r in tracked:
        names += write_arm_video(Path(dest), r.arm, model, r.track)
    return names, time.perf_counter() - lap


def is_video_name(name: str) -> bool:
    """Whether ``name`` is a file :func:`write_arm_video` writes (``<arm>.mp4``/``.gif``)."""
    from scenarios.lang.fields import NAME_RE

    stem, dot, suffix = name.rpartition(".")
    return bool(dot) and f".{suffix}" in VIDEO_SUFFIXES and bool(NAME_RE.match(stem))
