"""Facade of the Cassie plant + nominal walking controller used by the co-simulation.

Typical use::

    walker = CassieWalker(load_model("menagerie"))
    walker.set_command(0.5, 0.0)
    regulator = Regulator(RegulatorParams(adaptation_enabled=False))  # fmu_src.core.avr_core
    while walker.time_s < 10:
        apply_regulator(walker, regulator, 0.01)  # scenarios.cosim.inprocess
        walker.advance(20)          # 20 plant steps of 0.5 ms = 10 ms
        log(walker.telemetry())

The walker starts in the ``home`` standing pose at rest, stands
``ControllerParams.stand_time_s``, shifts its weight over the first stance foot
and then walks (see ``plant/controller.py`` for the signs of the offsets and the
definition of the regulator inputs).  The joint PD runs inside MuJoCo at every
plant step; the Python controller refreshes its targets every
``ControllerParams.control_substeps`` steps, counted across ``advance`` calls.

The plant imports nothing of the regulator: ``scenarios.cosim.inprocess.apply_regulator``
steps a regulator core on a walker in-process (the gait calibration, the plant tests and the
plant benchmark use it; the scenario suite has its own data flow in ``scenarios/cosim/master.py``).
"""
from __future__ import annotations

import ctypes
import logging
import math
from pathlib import Path
from typing import Mapping, Sequence

import mujoco

from plant.cassie import FALL_HEIGHT_M, FALL_TILT_RAD, CassiePhysics
from plant.constants import CONTROLLERS, OFFSET_NAMES
from plant.controller_params import ControllerParams
from plant.controller import NominalController
from plant.gaits import GaitLibrary
from plant.interface import inputs_of, signal_pickers, telemetry_of
from plant.native.native_ctrl import SENSE_NAMES

log = logging.getLogger(__name__)

#: Where the C controller is built when no library is given: ``build/`` of the checkout
#: (ignored by git), one folder per version of its sources.
NATIVE_CACHE = Path(__file__).resolve().parents[1] / "build" / "native_ctrl"


#: :meth:`CassieWalker.signals` out of the sensed signals (``SENSE_NAMES``): the regulator's ``vx`` and
#: ``vy`` are the step average and the filtered lateral speed, the telemetry's ``vy_signal`` the latter.
_HEAD, _TAIL = signal_pickers(SENSE_NAMES, {"vx": "vx_step_avg", "vy": "vy_filt"}, {"vy_signal": "vy_filt"})


class CassieWalker:
    """Cassie plant with the nominal controller (a :class:`plant.interface.Plant`); see the
    module docstring.

    Args:
        model: compiled Cassie model (``plant.model.load_model``), already carrying
            any perturbation; it is copied (and its actuators turned into PD
            servos on the copy), the caller's object is not changed.
        params: controller parameters (``ControllerParams``); defaults if None.
        gaits: gait library; the committed ``plant/data/gait_library.json`` if None.
        controller: the nominal controller's implementation, one of :data:`CONTROLLERS`:
            ``python`` (:class:`plant.controller.NominalController`) or ``native`` (the C
            controller of ``plant/native/``, the same doubles operation for operation:
            ``tests/plant/test_native_controller.py``).
        native_library: the loaded C controller (``plant.native.native_ctrl.NativeLibrary``) for
            ``controller="native"``; None: built once under :data:`NATIVE_CACHE` and loaded once
            per process.

    The fall check runs at the end of every :meth:`advance` and is latched.
    Pelvis forces from :meth:`set_pelvis_force` persist until changed.
    """

    def __init__(self, model: mujoco.MjModel, params: ControllerParams | None = None,
                 gaits: GaitLibrary | None = None, controller: str = "python", native_library=None):
        if controller not in CONTROLLERS:
            raise ValueError(f"controller = {controller!r}: must be one of {', '.join(CONTROLLERS)}")
        self.physics = CassiePhysics(model)
        #: Plant step (s), 0.5 ms for Cassie.
        self.SIM_DT_S = self.physics.SIM_DT_S
        self.params = params or ControllerParams()
        self.gaits = gaits or GaitLibrary.default()
        #: The controller's implementation, one of :data:`CONTROLLERS`.
        self.controller_kind = controller
        if controller == "native":
            from plant.native.native_ctrl import NativeController, cached_library_path, load_library

            if native_library is None:
                native_library = load_library(cached_library_path(NATIVE_CACHE))
            self.physics.configure_pd_servos()  # as NominalController does before its first update
            self.controller = NativeController(native_library, self.physics, self.params)
        else:
            self.controller = NominalController(self.physics, self.params)
        c_loop = controller == "native"
        #: The stepping, the fall test and the sensing, in C when the C controller runs (the same
        #: bits: tests/plant/test_native_controller.py): one call each per communication step.
        self._step = self._step_c if c_loop else self._step_python
        self._fallen = self._fallen_c if c_loop else self.physics.fell
        self._signals = self.controller.sense if c_loop else self._signals_python
        #: Simulated time of the state whose fall check :meth:`advance` made (None: not checked).
        self._fall_checked_t = None
        #: Plant steps since the controller's last update, counted across :meth:`advance` calls.
        self._substep = ctypes.c_int(0) if c_loop else 0
        self._fall_reason = None
        self.vx_des = 0.0
        self.vy_des = 0.0
        self.yaw_rate_des = 0.0
        self.set_command(0.0, 0.0)

    @property
    def model(self) -> mujoco.MjModel:
        """The walker's own (copied, servo-configured) model."""
        return self.physics.model

    @property
    def data(self) -> mujoco.MjData:
        return self.physics.data

    @property
    def time_s(self) -> float:
        """Simulated time (s)."""
        return self.physics.time_s

    def set_command(self, vx_des: float, vy_des: float, yaw_rate_des: float = 0.0) -> None:
        """Commanded forward/lateral speed (m/s, heading frame; selects the gait) and
        turning rate (rad/s, positive turns left); the controller follows them through
        its rate limits (``NominalController.vx_ref``, ...)."""
        self.vx_des, self.vy_des = float(vx_des), float(vy_des)
        self.yaw_rate_des = float(yaw_rate_des)
        self.controller.set_command(self.vx_des, self.vy_des, self.gaits, self.yaw_rate_des)

    def set_offsets(self, offsets: Mapping[str, float]) -> None:
        """Regulator joint offsets (rad); keys from ``OFFSET_NAMES``; unknown key -> KeyError."""
        self.controller.set_offsets(offsets)

    def set_offset_values(self, values: Sequence[float]) -> None:
        """:meth:`set_offsets` of the six offsets in ``OFFSET_NAMES``' order."""
        if self.controller_kind == "native":
            self.controller.set_offset_values(values)
        else:
            self.controller.set_offsets(dict(zip(OFFSET_NAMES, values, strict=True)))

    def signals(self) -> tuple:
        """The values of :meth:`regulator_inputs` then of :meth:`telemetry` (``step_index`` a
        float holding a whole number) in one call: ``plant.interface.Plant.signals``."""
        s = self._signals()
        return (*_HEAD(s), self.vx_des, self.vy_des, *_TAIL(s), self.yaw_rate_des)

    def regulator_inputs(self) -> dict:
        """Signals for the regulator (see ``plant/controller.py`` for definitions)."""
        return inputs_of(self.signals())

    def _signals_python(self) -> tuple:
        """What the C controller's ``sense`` gives (``plant.native.native_ctrl.SENSE_NAMES``), from
        the Python controller and the physics."""
        ph, c = self.physics, self.controller
        p = ph.pelvis_position()
        fl, fr = ph.foot_normal_forces_n()
        return (*ph.heading_state(), float(fl), float(fr), float(p[0]), float(p[1]), float(p[2]), self.time_s,
                float(c.vx_step_avg), float(c.vy_filt), float(c.step_index), 0.0 if c.stance == "left" else 1.0,
                float(c.tau))

    def advance(self, n_steps: int) -> None:
        """Advance ``n_steps`` plant steps of ``SIM_DT_S`` with the controller running."""
        n = int(n_steps)
        if n < 0:
            raise ValueError(f"n_steps must be >= 0, got {n_steps}")
        self._step(n)
        ph = self.physics
        if self._fall_reason is None:
            self._fall_reason = ph.fall_reason() if self._fallen() else None
            self._fall_checked_t = ph.data.time
            if self._fall_reason:
                log.info("fall at t=%.3f s: %s", self.time_s, self._fall_reason)

    def _step_python(self, n: int) -> None:
        sub = self.params.control_substeps
        ph, c = self.physics, self.controller
        while n > 0:
            k = min(n, sub - self._substep)
            ph.step(k)
            n -= k
            self._substep += k
            if self._substep >= sub:
                self._substep = 0
                c.update()

    def _step_c(self, n: int) -> None:
        self.controller.advance(n, self._substep)

    def _fallen_c(self) -> bool:
        return self.controller.fallen(FALL_HEIGHT_M, FALL_TILT_RAD)

    def _python_controller_only(self, what: str) -> None:
        if self.controller_kind != "python":
            raise NotImplementedError(f"{what}: the C controller's memory is not saved or restored; "
                                      "build the walker with controller='python' (the same trajectory)")

    def get_state(self) -> dict:
        """Everything needed to continue exactly from here: MuJoCo's integration state with
        the servo gains, the walker's and the controller's memory (plain Python values).
        The Python controller only (NotImplementedError with the C one)."""
        self._python_controller_only("get_state")
        return {"physics": self.physics.physics_state().tolist(),
                "walker": {"substep": self._substep, "fall_reason": self._fall_reason,
                           "vx_des": self.vx_des, "vy_des": self.vy_des,
                           "yaw_rate_des": self.yaw_rate_des},
                "controller": self.controller.memory()}

    def set_state(self, state: Mapping) -> None:
        """Restore :meth:`get_state` of a walker on the same model and gaits.

        Raises ValueError naming every problem (:meth:`state_problems`) when the state is not
        one this walker can have reached, ValueError/KeyError/TypeError when it does not fit;
        the walker is then as it was.  The Python controller only (NotImplementedError with the C one).
        """
        self._python_controller_only("set_state")
        backup = self.get_state()
        try:
            self._apply_state(state)
        except Exception:
            self._apply_state(backup)
            raise

    #: The walker's own fields in a state (besides the physics and the controller's memory).
    WALKER_FIELDS = ("substep", "fall_reason", "vx_des", "vy_des", "yaw_rate_des")

    def state_problems(self, state) -> list[str]:
        """Why ``state`` is not what :meth:`get_state` of this walker can have returned (every
        problem, each naming the field and its allowed values), or [] if it is: the physics
        (``CassiePhysics.physics_state_problems``), the controller's memory
        (``NominalController.memory_problems``) and the walker's own fields."""
        self._python_controller_only("state_problems")
        if not (isinstance(state, Mapping) and set(state) == {"physics", "walker", "controller"}):
            return ["walker state must be a table of exactly physics, walker and controller"]
        walker = state["walker"]
        if not (isinstance(walker, Mapping) and set(walker) == set(self.WALKER_FIELDS)):
            return [f"walker fields must be exactly {', '.join(self.WALKER_FIELDS)}"]
        problems = self.physics.physics_state_problems(state["physics"])
        substep, sub = walker["substep"], self.params.control_substeps
        if isinstance(substep, bool) or not isinstance(substep, int) or not 0 <= substep < sub:
            problems.append(f"walker substep = {substep!r}: must be an int in [0, {sub})")
        if not (walker["fall_reason"] is None or isinstance(walker["fall_reason"], str)):
            problems.append(f"walker fall_reason = {walker['fall_reason']!r}: must be null or a text")
        bound = self.physics.MAX_STATE_VALUE
        for name in ("vx_des", "vy_des", "yaw_rate_des"):
            value = walker[name]
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not -bound <= value <= bound:
                problems.append(f"walker {name} = {value!r}: must be a finite number in [{-bound:g}, {bound:g}]")
        try:  # the controller's step times are ordered up to the physics' time
            time_s = float(state["physics"][0])
        except (TypeError, ValueError, IndexError, KeyError):
            time_s = math.inf
        return problems + self.controller.memory_problems(state["controller"], time_s)

    def _apply_state(self, state: Mapping) -> None:
        problems = self.state_problems(state)
        if problems:
            raise ValueError("invalid walker state: " + "; ".join(problems))
        walker = state["walker"]
        substep = walker["substep"]
        self.physics.set_physics_state(state["physics"])
        self.controller.restore_memory(state["controller"])
        self._substep = substep
        self._fall_reason = walker["fall_reason"]
        self._fall_checked_t = None
        self.vx_des, self.vy_des = float(walker["vx_des"]), float(walker["vy_des"])
        self.yaw_rate_des = float(walker["yaw_rate_des"])

    def set_pelvis_force(self, force_n) -> None:
        """Constant world-frame force (N, 3-vector) on the pelvis until changed."""
        self.physics.set_pelvis_force(force_n)

    def set_body_force(self, body: str, force_n) -> None:
        """Constant world-frame force (N, 3-vector) at the COM of the model's body ``body``
        until changed (a push on a link other than the pelvis); KeyError for an unknown body."""
        import numpy as np

        bid = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_BODY, body)
        if bid <= 0:
            raise KeyError(f"body {body!r}: the model has no such body")
        f = np.asarray(force_n, dtype=float).reshape(3)
        if not np.all(np.isfinite(f)):
            raise ValueError(f"force_n must be finite, got {f}")
        self.data.xfrc_applied[bid, :3] = f

    def change_plant(self, **changes) -> None:
        """Change the walker's own model while it walks (an event): ``torso_mass_kg``,
        ``torso_com_shift_m``, ``damping_factor``, ``floor_friction``
        (:func:`plant.perturbation.change_plant`)."""
        from plant.perturbation import change_plant

        change_plant(self.model, **changes)
        log.info("t=%.3f s: plant changed: %s", self.time_s, changes)

    def fell(self) -> bool:
        """True once a fall has been detected (latched; checked at the end of ``advance``)."""
        if self._fall_reason is None and self._fall_checked_t != self.physics.data.time:
            self._fall_reason = self.physics.fall_reason()  # a state advance did not check
        return self._fall_reason is not None

    @property
    def fall_reason(self) -> str | None:
        """Reason of the first detected fall, or None."""
        return self._fall_reason

    def close(self) -> None:
        """Nothing to free (the model and data are Python objects); part of :class:`plant.interface.Plant`."""

    def telemetry(self) -> dict:
        """Named floats for logging (SI units; stance 0 = left, 1 = right): ``TELEMETRY_NAMES``."""
        return telemetry_of(self.signals())


__all__ = ["CassieWalker"]
