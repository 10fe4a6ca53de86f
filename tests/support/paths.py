"""Where things are, for every test."""
from pathlib import Path

#: The checkout's root folder.
REPO_ROOT = Path(__file__).resolve().parents[2]
#: This folder: the shared helpers, the FMI drivers (``fmi/``) and the C hosts (``native/``).
SUPPORT_DIR = Path(__file__).resolve().parent


def _model_env() -> dict[str, str]:
    from plant import model

    env = {"CASSIE_OSU_XML": str(model.osu_model_path().resolve())}
    root = model.menagerie_root()
    if root is not None:
        env["MENAGERIE_ROOT"] = str(root.resolve())
    return env


#: The model loader's locations (``MENAGERIE_ROOT``, ``CASSIE_OSU_XML``: from the environment, else
#: the defaults beside the checkout) as absolute paths, resolved once when the tests are collected:
#: for a process the tests start in another folder, or on a copy of the code that is not beside
#: ``shared/``. ``MENAGERIE_ROOT`` is left out when there is none (the mujoco-menagerie cache).
MODEL_ENV = _model_env()
