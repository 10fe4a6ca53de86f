"""The regulator's three fixed hidden layers of LIFRate neurons (nengo's ``neurons.py`` and
``ensemble.py`` in spirit).

Each network has ``n_neurons`` LIFRate neurons (``TAU_RC``, ``TAU_REF``) with unit
encoders uniform on the sphere, maximum rates uniform in ``MAX_RATE_RANGE_HZ`` and
intercepts uniform in ``INTERCEPT_RANGE`` (nengo 4's Ensemble defaults, radius 1);
gains and biases follow from the analytic LIF rate curve (:func:`lif_gain_bias`).
The random numbers are SplitMix64 counter streams keyed by (seed, network, field)
(:class:`SplitMix64`, :func:`sphere_encoders`), so the C core (``native/``) builds the
same networks from the same seed.  :func:`scaled_inputs` maps the measurements into the
networks' unit balls; :func:`lif_rates_times_tau_rc` evaluates all neurons at once.
The method: ``docs/method.md``.

Bit-identical on every machine: everything here, and every call of the regulator, is a
fixed sequence of float64 ``+ - * /``, ``sqrt`` and ``frexp`` (each exact or correctly
rounded by IEEE 754), in a fixed order.  No libm or SIMD ``log1p``/``expm1``/``hypot``
(their last bits differ between libraries and CPUs: numpy's AVX-512 ``log1p`` differs
from glibc's on ~5% of arguments) and no BLAS (its summation order and FMA use depend
on the CPU): :func:`log1p_fixed` and :func:`expm1_fixed` are short series, the dot
products are sequential sums.  The C core (``native/avr_model.c``) performs the same
operations in the same order, so the two cores give the same bits on every IEEE 754
machine, and a run is reproducible across machines.
"""
from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field

import numpy as np

__all__ = [
    "TAU_RC", "TAU_REF", "MAX_RATE_RANGE_HZ", "INTERCEPT_RANGE", "NETWORK_NAMES",
    "NETWORK_DIMENSIONS", "INV_TAU_RC", "lif_gain_bias", "NetworkSpec", "SplitMix64",
    "sphere_encoders", "Networks", "build_networks", "lif_rates_times_tau_rc",
    "scaled_inputs", "input_currents", "readonly", "LN2", "SQRT2", "log1p_fixed", "expm1_fixed",
    "EXPM1_FIXED_MAX",
]

logger = logging.getLogger(__name__)

#: LIFRate membrane time constant (s) and refractory period (s).
TAU_RC = 0.02
TAU_REF = 0.002
#: Distributions of the neurons' maximum rates (Hz, uniform) and intercepts (uniform,
#: in units of the unit-ball input), both nengo 4's Ensemble defaults.  The intercepts
#: stay below 1: the gain ``(J_max - 1) / (1 - intercept)`` diverges as one approaches 1.
MAX_RATE_RANGE_HZ = (200.0, 400.0)
INTERCEPT_RANGE = (-1.0, 0.9)
#: The networks, in stream order (the ``net`` of :class:`SplitMix64`), and their input
#: dimensions: [vx, vx_des], [vy, vy_des], [pitch, roll, pitch_rate, roll_rate].
NETWORK_NAMES = ("longitudinal", "lateral", "torso")
NETWORK_DIMENSIONS = (2, 2, 4)
#: The :class:`SplitMix64` ``field`` of each random quantity.
_ENCODER_FIELD, _MAX_RATE_FIELD, _INTERCEPT_FIELD = 0, 1, 2
_TAU_RATIO = TAU_REF / TAU_RC
INV_TAU_RC = 1.0 / TAU_RC
#: A tiny positive current for inactive neurons (keeps inf out of log1p's slow path).
_TINY_CURRENT = 1e-300

#: ln 2 and sqrt 2, rounded to nearest (the C core has them from the generated header).
LN2 = float.fromhex("0x1.62e42fefa39efp-1")
SQRT2 = float.fromhex("0x1.6a09e667f3bcdp+0")


def _series_coefficients():
    """``2 / (2i + 1)`` for i = 1..9 (atanh) and ``1 / i!`` for i = 1..20 (exp), each one
    correctly rounded division of exact operands (20! is exact in float64)."""
    atanh = tuple(2.0 / (2 * i + 1) for i in range(1, 10))
    exp, factorial = [], 1.0
    for i in range(1, 21):
        factorial = factorial * i
        exp.append(1.0 / factorial)
    return atanh, tuple(exp)


_ATANH_COEFFS, _EXP_COEFFS = _series_coefficients()
#: :func:`expm1_fixed` serves 0 <= x <= EXPM1_FIXED_MAX (max rates >= 1 / (tau_ref + tau_rc)).
EXPM1_FIXED_MAX = 1.0


def _horner_tail(coefficients, z):
    """``sum_i coefficients[i-1] z^i`` as ``(...((c_n z + c_{n-1}) z + ...) + c_1) z``."""
    total = coefficients[-1] * z
    for coefficient in coefficients[-2::-1]:
        total += coefficient
        total *= z
    return total


def expm1_fixed(x: np.ndarray) -> np.ndarray:
    """``exp(x) - 1`` for ``0 <= x <= 1`` (array), the same bits on every machine.

    The Taylor series to x^20, by Horner: the first omitted term is below 2e-20 x, so
    the result is within a few ulp of the exact value.
    """
    x = np.asarray(x, dtype=np.float64)
    if not np.all((x >= 0.0) & (x <= EXPM1_FIXED_MAX)):
        raise ValueError(f"expm1_fixed needs 0 <= x <= {EXPM1_FIXED_MAX}")
    return _horner_tail(_EXP_COEFFS, x)


def log1p_fixed(y: np.ndarray) -> np.ndarray:
    """``log(1 + y)`` for finite ``y >= 0`` (array, overwritten), the same bits on every machine.

    ``u = 1 + y`` (rounded); ``u = m' 2^k`` with m' in [1/2, 1) (``frexp``, exact); ``m =
    m' sqrt2`` in [0.707, 1.415); ``s = (m - 1) / (m + 1)``, |s| < 0.172; ``log u = (k -
    1/2) ln2 + 2 atanh(s)`` with ``2 atanh(s) = s (2 + sum_{i=1..9} 2/(2i+1) s^(2i))``
    (first omitted term < 3e-17 relative).  Error: ~2e-16 relative plus up to ~3e-16
    absolute (the rounding of ``1 + y``, and of the two terms near u = 1), i.e. relative
    ~1e-14 at the regulator's smallest argument, y = 1/40.
    """
    np.add(y, 1.0, out=y)
    mantissa, exponent = np.frexp(y)
    mantissa *= SQRT2
    s = mantissa - 1.0
    mantissa += 1.0
    s /= mantissa
    z = np.multiply(s, s, out=mantissa)
    tail = _horner_tail(_ATANH_COEFFS, z)
    tail += 2.0
    tail *= s
    result = np.subtract(exponent, 0.5, out=y)  # exact: a small integer minus 1/2
    result *= LN2
    result += tail
    return result


def readonly(array: np.ndarray) -> np.ndarray:
    """``array``, made read-only (states and networks share nothing mutable)."""
    array.flags.writeable = False
    return array


def lif_gain_bias(max_rates, intercepts, tau_rc: float = TAU_RC,
                  tau_ref: float = TAU_REF) -> tuple[np.ndarray, np.ndarray]:
    """Gain and bias (per neuron, unit input current) of LIFRate neurons.

    The LIF rate for input current J > 1 is ``1 / (tau_ref + tau_rc ln(1 + 1/(J-1)))``.
    A neuron with intercept c (rate 0 at ``e.x = c``, i.e. ``J = 1``) and maximum rate
    m (Hz, reached at ``e.x = 1``) needs ``J_max - 1 = 1 / expm1((1/m - tau_ref) /
    tau_rc)``, hence ``gain = (J_max - 1) / (1 - c)`` and ``bias = 1 - gain c``.
    Requires ``1/(tau_ref + tau_rc) <= m < 1/tau_ref`` (45.5-500 Hz for the defaults;
    :func:`expm1_fixed`'s domain) and ``c < 1``.
    """
    max_rates = np.asarray(max_rates, dtype=np.float64)
    intercepts = np.asarray(intercepts, dtype=np.float64)
    lowest = 1.0 / (tau_ref + tau_rc * EXPM1_FIXED_MAX)
    if np.any(max_rates >= 1.0 / tau_ref) or not np.all(max_rates >= lowest):
        raise ValueError(f"max_rates must be in [{lowest:.6g}, {1.0 / tau_ref:.6g}) Hz")
    if np.any(intercepts >= 1.0):
        raise ValueError("intercepts must be < 1")
    j_max_minus_1 = 1.0 / expm1_fixed((1.0 / max_rates - tau_ref) / tau_rc)
    gain = j_max_minus_1 / (1.0 - intercepts)
    bias = 1.0 - gain * intercepts
    return gain, bias


@dataclass(frozen=True, eq=False)
class NetworkSpec:
    """One fixed hidden layer: ``n`` LIFRate neurons on a ``d``-dimensional input.

    ``encoders`` (n, d) unit vectors, ``max_rates`` (n,) Hz, ``intercepts`` (n,),
    ``gain`` (n,) and ``bias`` (n,) in units of the neuron's threshold current, and
    ``scaled_encoders = encoders * gain[:, None]`` (radius 1).  Input current for a
    unit-ball input x: ``J = scaled_encoders @ x + bias``.  Arrays are read-only.
    """

    name: str
    encoders: np.ndarray
    max_rates: np.ndarray
    intercepts: np.ndarray
    gain: np.ndarray
    bias: np.ndarray
    scaled_encoders: np.ndarray

    @property
    def n_neurons(self) -> int:
        return self.encoders.shape[0]

    @property
    def dimensions(self) -> int:
        return self.encoders.shape[1]


class SplitMix64:
    """The networks' random numbers: SplitMix64 streams, one per (seed, network, field).

    SplitMix64 (Steele, Lea and Flood, OOPSLA 2014; the generator Vigna recommends for
    seeding xoshiro) is a counter passed through a 64-bit finaliser, so the C core
    (``native/avr_model.c``) computes exactly the same integers.  All arithmetic is on
    unsigned 64-bit integers modulo 2**64::

        mix(z) = z3 ^ (z3 >> 31),  z3 = (z2 ^ (z2 >> 27)) * 0x94D049BB133111EB,
                                   z2 = (z  ^ (z  >> 30)) * 0xBF58476D1CE4E5B9
        key(seed, net, field) = mix(16 seed + 4 net + field)
        draw i (i = 0, 1, ...) = mix(key + (i + 1) * 0x9E3779B97F4A7C15)
        uniform_i = (draw_i >> 11) * 2**-53                     in [0, 1), exact

    ``net`` is 0 (longitudinal), 1 (lateral), 2 (torso); ``field`` is 0 (encoders),
    1 (max rates), 2 (intercepts).  Distinct (seed, net, field) give distinct keys
    (``mix`` is a bijection), so the nine streams of a seed never overlap in practice.
    """

    GAMMA = 0x9E3779B97F4A7C15
    _M1 = np.uint64(0xBF58476D1CE4E5B9)
    _M2 = np.uint64(0x94D049BB133111EB)
    _SHIFTS = (np.uint64(30), np.uint64(27), np.uint64(31))
    #: Stream key: ``KEY_SEED_STRIDE seed + KEY_NET_STRIDE net + field``.
    KEY_SEED_STRIDE, KEY_NET_STRIDE = 16, 4
    #: A double in [0, 1) from the top 53 bits of a draw.
    _MANTISSA_SHIFT = np.uint64(64 - 53)
    _ULP = 2.0**-53

    def __init__(self, seed: int, net: int, field: int):
        start = self.KEY_SEED_STRIDE * seed + self.KEY_NET_STRIDE * net + field
        self.key = int(self.mix(np.array([start], dtype=np.uint64))[0])
        self.next_index = 0

    @classmethod
    def mix(cls, bits: np.ndarray) -> np.ndarray:
        """The SplitMix64 finaliser on a uint64 array (wrapping arithmetic)."""
        shift1, shift2, shift3 = cls._SHIFTS
        bits = (bits ^ (bits >> shift1)) * cls._M1
        bits = (bits ^ (bits >> shift2)) * cls._M2
        return bits ^ (bits >> shift3)

    def uniform(self, count: int) -> np.ndarray:
        """The next ``count`` doubles in [0, 1) of this stream."""
        draw = np.arange(self.next_index + 1, self.next_index + count + 1, dtype=np.uint64)
        self.next_index += count
        counters = np.uint64(self.key) + draw * np.uint64(self.GAMMA)
        return (self.mix(counters) >> self._MANTISSA_SHIFT).astype(np.float64) * self._ULP


def sphere_encoders(stream: SplitMix64, count: int, dims: int) -> np.ndarray:
    """``count`` unit vectors uniform on the sphere in R^dims, by rejection from the cube.

    Candidate j takes the next ``dims`` uniforms u of ``stream``, ``v = 2 u - 1`` (exact);
    ``r2 = (((v0 v0 + v1 v1) + v2 v2) + ...)`` in that order; it is accepted iff
    ``0 < r2 <= 1`` and becomes ``v / sqrt(r2)``.  Only correctly rounded IEEE
    operations, in a fixed order, so the C core gets the same bits.
    """
    accepted, have = [], 0
    while have < count:  # acceptance 79% (d = 2) or 31% (d = 4): one batch, rarely two
        # The field-0 stream serves the encoders only, so candidates drawn past the
        # last accepted one are simply never used: the accepted sequence is the one a
        # candidate-by-candidate loop (the C core's) finds.
        n_candidates = (count - have) * _CANDIDATES_PER_ENCODER + _EXTRA_CANDIDATES
        cube = 2.0 * stream.uniform(n_candidates * dims).reshape(-1, dims) - 1.0
        norm2 = cube[:, 0] * cube[:, 0]
        for axis in range(1, dims):
            norm2 = norm2 + cube[:, axis] * cube[:, axis]
        take = np.flatnonzero((norm2 > 0.0) & (norm2 <= 1.0))[:count - have]
        accepted.append(cube[take] / np.sqrt(norm2[take])[:, None])
        have += len(take)
    return np.concatenate(accepted) if accepted else np.zeros((0, dims))


#: Candidates drawn per missing encoder (and a few more) in one batch of
#: :func:`sphere_encoders`: above 1 / acceptance (3.2 for d = 4), so one batch nearly always suffices.
_CANDIDATES_PER_ENCODER, _EXTRA_CANDIDATES = 4, 16


def _make_network(name: str, n_neurons: int, dims: int, seed: int, net: int) -> NetworkSpec:
    encoders = sphere_encoders(SplitMix64(seed, net, _ENCODER_FIELD), n_neurons, dims)
    low, high = MAX_RATE_RANGE_HZ
    max_rates = low + (high - low) * SplitMix64(seed, net, _MAX_RATE_FIELD).uniform(n_neurons)
    low, high = INTERCEPT_RANGE
    intercepts = low + (high - low) * SplitMix64(seed, net, _INTERCEPT_FIELD).uniform(n_neurons)
    gain, bias = lif_gain_bias(max_rates, intercepts)
    scaled = encoders * gain[:, None]
    return NetworkSpec(name, readonly(encoders), readonly(max_rates), readonly(intercepts),
                       readonly(gain), readonly(bias), readonly(scaled))


@dataclass(frozen=True, eq=False)
class Networks:
    """The three fixed hidden layers, built from ``(n_neurons, seed)`` only.

    ``longitudinal`` (input [vx, vx_des]), ``lateral`` ([vy, vy_des]) and ``torso``
    ([pitch, roll, pitch_rate, roll_rate]), all scaled into the unit ball.

    For :func:`input_currents` (read-only): ``encoder_rows`` (2, 3, n), the first two
    columns of each network's scaled encoders ([d, k, i]: input d of network k, neuron
    i); ``torso_rows`` (2, n), the torso network's last two; ``bias_minus_1`` (3, n).
    """

    n_neurons: int
    seed: int
    longitudinal: NetworkSpec
    lateral: NetworkSpec
    torso: NetworkSpec
    encoder_rows: np.ndarray = field(init=False, repr=False)
    torso_rows: np.ndarray = field(init=False, repr=False)
    bias_minus_1: np.ndarray = field(init=False, repr=False)

    def __post_init__(self):
        n_neurons = self.n_neurons
        for net, dims in zip(self, NETWORK_DIMENSIONS):
            if net.encoders.shape != (n_neurons, dims):
                raise ValueError(f"{net.name}: encoders must have shape {(n_neurons, dims)}")
        rows = np.stack([net.scaled_encoders[:, :2].T for net in self], axis=1)
        torso_rows = np.ascontiguousarray(self.torso.scaled_encoders[:, 2:].T)
        bias_minus_1 = np.stack([net.bias for net in self]) - 1.0
        for name, array in (("encoder_rows", rows), ("torso_rows", torso_rows),
                            ("bias_minus_1", bias_minus_1)):
            object.__setattr__(self, name, readonly(np.ascontiguousarray(array)))

    def __iter__(self):
        return iter((self.longitudinal, self.lateral, self.torso))


def build_networks(params) -> Networks:
    """Build the three networks from ``params.n_neurons`` and ``params.seed`` only.

    Network k (0 longitudinal, 1 lateral, 2 torso) takes its encoders, maximum rates
    and intercepts from its own :class:`SplitMix64` streams (encoders uniform on the
    sphere by :func:`sphere_encoders`; ``max_rate = 200 + 200 u``, ``intercept = -1 +
    1.9 u``), so the networks are independent of each other, identical for identical
    seeds, and the same in the C core (bit for bit on glibc, whose ``expm1`` the gains
    go through; another libm may differ in the last bit of a gain).
    """
    n_neurons, seed = int(params.n_neurons), int(params.seed)
    nets = [_make_network(name, n_neurons, dims, seed, index)
            for index, (name, dims) in enumerate(zip(NETWORK_NAMES, NETWORK_DIMENSIONS))]
    logger.debug("built 3 networks of %d LIFRate neurons (seed %d)", n_neurons, seed)
    return Networks(n_neurons, seed, *nets)


def input_currents(x: list[float], networks: Networks) -> np.ndarray:
    """``J - 1`` of all neurons, (3, n), for the 8 scaled inputs ``x`` (:func:`scaled_inputs`).

    Neuron i of a network with inputs x_0..x_{d-1}: ``((x_0 e_0 + x_1 e_1) [+ x_2 e_2]
    [+ x_3 e_3]) + (bias - 1)`` with e the scaled encoder, in that order (as the C core).
    """
    first = np.array([[x[0], x[2], x[4]], [x[1], x[3], x[5]]])[:, :, None]
    products = networks.encoder_rows * first
    current = np.add(products[0], products[1], out=products[0])
    torso = networks.torso_rows * np.array([[x[6]], [x[7]]])
    current[2] += torso[0]
    current[2] += torso[1]
    current += networks.bias_minus_1
    return current


def lif_rates_times_tau_rc(current: np.ndarray) -> np.ndarray:
    """``tau_rc *`` LIFRate rate (dimensionless) for ``current = J - 1``, in place.

    ``tau_rc r = 1 / (tau_ref / tau_rc + log1p(1 / (J - 1)))`` where ``J > 1``, else 0
    (exactly 0 Hz), with :func:`log1p_fixed`: one pass fewer than nengo's ``1 / (tau_ref
    + tau_rc log1p(..))``; the regulator folds the factor ``1 / tau_rc`` (``INV_TAU_RC``)
    into four scalars.  Inactive neurons get a tiny positive current first (keeps inf
    out) and are zeroed by the last division.
    """
    active = current > 0.0
    np.maximum(current, _TINY_CURRENT, out=current)
    np.divide(1.0, current, out=current)
    log1p_fixed(current)
    current += _TAU_RATIO
    np.divide(active, current, out=current)  # True -> 1.0, False -> 0.0
    return current


def _into_unit_ball(values: list[float]) -> list[float]:
    """``values`` divided by their norm if it exceeds 1 (direction kept); the norm is
    ``sqrt(((v0 v0 + v1 v1) + v2 v2) + ...)`` in that order (no overflow: the inputs and
    scales are range-checked, |v| <= 1e4)."""
    norm2 = values[0] * values[0]
    for value in values[1:]:
        norm2 = norm2 + value * value
    norm = math.sqrt(norm2)
    if norm > 1.0:
        return [value / norm for value in values]
    return values


def scaled_inputs(vx, vx_des, vy, vy_des, pitch, roll, pitch_rate, roll_rate,
                  params) -> list[float]:
    """The 8 network inputs: longitudinal ``[vx, vx_des] / velocity_scale_mps``, lateral
    ``[vy, vy_des] / velocity_scale_mps``, torso ``[pitch / angle_scale_rad, roll /
    angle_scale_rad, pitch_rate / rate_scale_radps, roll_rate / rate_scale_radps]``
    (python floats in m/s, rad, rad/s), each then mapped into its unit ball by radial
    projection (:func:`_into_unit_ball`): a vector of norm <= 1 is kept, a longer one
    divided by its norm (direction kept).
    """
    velocity_scale, angle_scale = params.velocity_scale_mps, params.angle_scale_rad
    rate_scale = params.rate_scale_radps
    longitudinal = _into_unit_ball([vx / velocity_scale, vx_des / velocity_scale])
    lateral = _into_unit_ball([vy / velocity_scale, vy_des / velocity_scale])
    torso = _into_unit_ball([pitch / angle_scale, roll / angle_scale, pitch_rate / rate_scale,
                             roll_rate / rate_scale])
    return [*longitudinal, *lateral, *torso]
