"""The factors a campaign may vary: each maps a drawn value onto a scenario document.

A scenario document is the parsed TOML of a scenario file (see :mod:`scenarios.lang.spec`).
Every factor names the scenario key it sets; ``apply`` edits a deep copy of the base
document and returns ``None``, or the reason the factor cannot apply to that base
(checked once per campaign on the base, not per sample).

Kinds of values: ``number`` (float), ``integer``, ``bool``, ``terrain`` (``"flat"`` or a
``[terrain]`` table) and ``pushes`` (a list of ``[[push]]`` tables, ``[]`` for none).
``regulator.<parameter>`` sets any FMU parameter of the ``[regulator]`` table; its kind
follows the parameter's FMI type.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

#: Factors whose values are times on the communication grid: draws are snapped to it.
TIME_FACTORS = ("push_t_s", "push_duration_s")


@dataclass(frozen=True)
class FactorKind:
    kind: str  # number | integer | bool | terrain | pushes
    apply: Callable[[dict, Any], str | None]
    doc: str


def _set_top(key: str) -> Callable[[dict, Any], None]:
    def apply(doc: dict, value: Any) -> None:
        doc[key] = value
    return apply


def _set_com(axis: int) -> Callable[[dict, Any], None]:
    def apply(doc: dict, value: Any) -> None:
        com = list(doc.get("torso_com_offset_m", [0.0, 0.0, 0.0]))
        com[axis] = value
        doc["torso_com_offset_m"] = com
    return apply


def _set_command(key: str) -> Callable[[dict, Any], str | None]:
    def apply(doc: dict, value: Any) -> str | None:
        cmds = doc.get("command")
        if not isinstance(cmds, list) or len(cmds) != 1:
            n = len(cmds) if isinstance(cmds, list) else 0
            return f"needs a base with exactly one [[command]] (a constant command); the base has {n}"
        cmds[0] = {**cmds[0], key: value}
        return None
    return apply


def _set_terrain_key(key: str) -> Callable[[dict, Any], str | None]:
    def apply(doc: dict, value: Any) -> str | None:
        if not isinstance(doc.get("terrain"), dict):
            return "needs a base with a [terrain] table (and no `terrain` factor)"
        doc["terrain"] = {**doc["terrain"], key: value}
        return None
    return apply


def _set_push_key(key: str, axis: int | None = None) -> Callable[[dict, Any], str | None]:
    def apply(doc: dict, value: Any) -> str | None:
        pushes = doc.get("push")
        if not isinstance(pushes, list) or not pushes:
            return "needs a base with a [[push]] (it varies the first one; or use the `pushes` factor)"
        first = dict(pushes[0])
        if axis is None:
            first[key] = value
            if key == "t_s":  # convergence is measured from the push
                doc["perturbation_t_s"] = value
        else:
            force = list(first.get("force_n", [0.0, 0.0, 0.0]))
            force[axis] = value
            first["force_n"] = force
        pushes[0] = first
        return None
    return apply


def _set_terrain(doc: dict, value: Any) -> None:
    if value == "flat":
        doc.pop("terrain", None)
    else:
        doc["terrain"] = dict(value)


def _set_pushes(doc: dict, value: Any) -> None:
    if value:
        doc["push"] = [dict(p) for p in value]
    else:
        doc.pop("push", None)


def _set_table(key: str) -> Callable[[dict, Any], None]:
    """The whole ``[key]`` table (``"none"`` removes it)."""
    def apply(doc: dict, value: Any) -> str | None:
        if value == "none":
            doc.pop(key, None)
        else:
            if key == "command_profile":  # the profile replaces the schedule
                doc.pop("command", None)
            doc[key] = dict(value)
        return None
    return apply


def _set_table_key(table_key: str, key: str) -> Callable[[dict, Any], str | None]:
    def apply(doc: dict, value: Any) -> str | None:
        if not isinstance(doc.get(table_key), dict):
            if table_key == "command_profile" and (doc.get("command") or "command_profile" in doc):
                return None  # this sample has no profile (a `command_profile` choice of "none")
            if table_key == "random_pushes" and "random_pushes" not in doc:
                return None
            return f"needs a base with a [{table_key}] table or a `{table_key}` factor"
        doc[table_key] = {**doc[table_key], key: value}
        return None
    return apply


def _set_floor(doc: dict, value: Any) -> None:
    """``"flat"``, or a table of any of slope_deg, cross_slope_deg, terrain (a [terrain]
    table): the floor's shape; drops what the base had."""
    for key in ("terrain", "slope_deg", "cross_slope_deg"):
        doc.pop(key, None)
    if value != "flat":
        doc.update({k: (dict(v) if isinstance(v, dict) else v) for k, v in value.items()})


def _set_floor_terrain_seed(doc: dict, value: Any) -> None:
    if isinstance(doc.get("terrain"), dict):
        doc["terrain"] = {**doc["terrain"], "seed": value}


def _set_link_mass(body: str) -> Callable[[dict, Any], None]:
    def apply(doc: dict, value: Any) -> None:
        links = [dict(t) for t in doc.get("link_mass", []) if t.get("body") != body]
        doc["link_mass"] = links + [{"body": body, "scale": value}]
    return apply


def _set_regulator(param: str) -> Callable[[dict, Any], None]:
    def apply(doc: dict, value: Any) -> None:
        doc["regulator"] = {**doc.get("regulator", {}), param: value}
    return apply


#: Built-in factors in the order they are applied (a whole table before its keys).
FACTORS: dict[str, FactorKind] = {
    "torso_mass_kg": FactorKind("number", _set_top("torso_mass_kg"), "absolute torso (pelvis) mass, kg"),
    "torso_added_mass_kg": FactorKind("number", _set_top("torso_added_mass_kg"), "mass added to the torso, kg"),
    "torso_com_offset_x_m": FactorKind("number", _set_com(0), "torso COM offset, x (forward), m"),
    "torso_com_offset_y_m": FactorKind("number", _set_com(1), "torso COM offset, y (left), m"),
    "torso_com_offset_z_m": FactorKind("number", _set_com(2), "torso COM offset, z (up), m"),
    "joint_damping_scale": FactorKind("number", _set_top("joint_damping_scale"), "joint damping multiplier"),
    "vx_des": FactorKind("number", _set_command("vx_des"), "commanded forward speed, m/s (the one [[command]])"),
    "vy_des": FactorKind("number", _set_command("vy_des"), "commanded lateral speed, m/s (the one [[command]])"),
    "yaw_rate_des": FactorKind("number", _set_command("yaw_rate_des"),
                               "commanded turning rate, rad/s, positive left (the one [[command]])"),
    "seed": FactorKind("integer", _set_top("seed"), "the regulator's network weight seed"),
    "terrain": FactorKind("terrain", _set_terrain, "\"flat\" or a [terrain] table"),
    "terrain_max_height_m": FactorKind("number", _set_terrain_key("max_height_m"), "terrain.max_height_m"),
    "terrain_max_slope_deg": FactorKind("number", _set_terrain_key("max_slope_deg"), "terrain.max_slope_deg"),
    "terrain_seed": FactorKind("integer", _set_terrain_key("seed"), "terrain.seed"),
    "pushes": FactorKind("pushes", _set_pushes, "a list of [[push]] tables ([] for none)"),
    "push_t_s": FactorKind("number", _set_push_key("t_s"), "push[0].t_s and perturbation_t_s (snapped to the comm grid)"),
    "push_duration_s": FactorKind("number", _set_push_key("duration_s"), "push[0].duration_s (snapped)"),
    "push_force_x_n": FactorKind("number", _set_push_key("force_n", 0), "push[0].force_n x, N"),
    "push_force_y_n": FactorKind("number", _set_push_key("force_n", 1), "push[0].force_n y, N"),
    "push_force_z_n": FactorKind("number", _set_push_key("force_n", 2), "push[0].force_n z, N"),
    "model": FactorKind("model", _set_top("model"), "the model: \"menagerie\" or \"osu\""),
    "floor_friction": FactorKind("number", _set_top("floor_friction"), "floor friction, (0, 2]"),
    "floor": FactorKind("floor", _set_floor, "\"flat\" or a table of slope_deg, cross_slope_deg or terrain "
                                             "(a [terrain] table): the floor's shape"),
    "floor_terrain_seed": FactorKind("integer", _set_floor_terrain_seed,
                                     "terrain.seed of a sample whose floor has a terrain (else nothing)"),
    "slope_deg": FactorKind("number", _set_top("slope_deg"), "constant floor slope along x, deg"),
    "cross_slope_deg": FactorKind("number", _set_top("cross_slope_deg"), "constant floor slope along y, deg"),
    "command_profile": FactorKind("table", _set_table("command_profile"),
                                  "a [command_profile] table (replaces [[command]]), or \"none\""),
    "command_profile_seed": FactorKind("integer", _set_table_key("command_profile", "seed"),
                                       "command_profile.seed"),
    "random_pushes": FactorKind("table", _set_table("random_pushes"), "a [random_pushes] table, or \"none\""),
    "random_pushes_seed": FactorKind("integer", _set_table_key("random_pushes", "seed"), "random_pushes.seed"),
    "random_pushes_count": FactorKind("integer", _set_table_key("random_pushes", "count"), "random_pushes.count"),
}
REGULATOR_PREFIX = "regulator."
#: ``link_mass_scale.<body>``: that link's mass factor (a [[link_mass]] entry with scale).
LINK_MASS_PREFIX = "link_mass_scale."


def lookup(name: str) -> FactorKind | None:
    """The factor called ``name`` (``regulator.<param>`` for FMU parameters), or None."""
    if name in FACTORS:
        return FACTORS[name]
    if name.startswith(LINK_MASS_PREFIX) and len(name) > len(LINK_MASS_PREFIX):
        body = name[len(LINK_MASS_PREFIX):]
        return FactorKind("number", _set_link_mass(body), f"mass factor of the link {body}")
    if name.startswith(REGULATOR_PREFIX):
        from scenarios.lang.sections import regulator_param_specs

        spec = regulator_param_specs().get(name[len(REGULATOR_PREFIX):])
        if spec is None:
            return None
        kind = str(spec.type).lower()
        kind = "bool" if kind.startswith("bool") else "integer" if kind.startswith("int") else "number"
        return FactorKind(kind, _set_regulator(spec.name), spec.description)
    return None


def known_names() -> list[str]:
    from scenarios.lang.sections import regulator_param_specs

    return list(FACTORS) + [REGULATOR_PREFIX + p for p in regulator_param_specs()]


def apply_order(names) -> list[str]:
    """Built-in factors in catalogue order, then ``regulator.*`` by name."""
    builtin = [n for n in FACTORS if n in names]
    return builtin + sorted(n for n in names if n not in FACTORS)


def value_ok(kind: str, value: Any) -> bool:
    """Is ``value`` of the factor kind (ranges are the scenario validator's business)?"""
    is_num = isinstance(value, (int, float)) and not isinstance(value, bool)
    if kind == "number":
        return is_num
    if kind == "integer":
        return isinstance(value, int) and not isinstance(value, bool)
    if kind == "bool":
        return isinstance(value, bool)
    if kind == "terrain":
        return value == "flat" or isinstance(value, dict)
    if kind == "pushes":
        return isinstance(value, list) and all(isinstance(p, dict) for p in value)
    if kind == "model":
        return value in ("menagerie", "osu")
    if kind == "floor":
        return value == "flat" or (isinstance(value, dict) and bool(value)
                                    and set(value) <= {"slope_deg", "cross_slope_deg", "terrain"})
    if kind == "table":
        return value == "none" or isinstance(value, dict)
    return False


KIND_HINT = {
    "number": "a number", "integer": "an integer", "bool": "true or false",
    "terrain": "\"flat\" or a [terrain] table", "pushes": "a list of push tables",
    "model": "\"menagerie\" or \"osu\"",
    "floor": "\"flat\" or a table of slope_deg, cross_slope_deg or terrain",
    "table": "a table, or \"none\"",
}
