"""Fit the MuJoCo model behind the command layer with MuJoCo's own system identification (``mujoco.sysid``):
``bigcbf calibrate LOG --model DIR``.

The command layer (twin.calibrate / twin.replay: latency, wheel-speed and acceleration limits, bias) stays in front;
what it cannot express is the model's physics. Fitted parameters (``mujoco.sysid.Parameter`` each, with an MjSpec
modifier; the model is recompiled from the robot's ``scene.xml`` for every candidate):

- ``wheel_kv`` [N m s/rad]: the wheel velocity actuators' gain (all four alike);
- ``wheel_damping`` [N m s/rad]: the wheel joints' viscous damping (with kv, the wheels' steady-state gain
  kv / (kv + damping) and their time constant);
- ``floor_friction`` [-]: the sliding friction of the roller/floor contact (the floor geom has priority, so its
  friction is the contact's): roller slip, above all in yaw;
- ``base_mass`` [kg]: the chassis' mass (the body's inertia follows from its geometry), kept only where the log
  identifies it.

What the log measures (the residual): the odometry's body twist (vx, vy from the wheel encoders; wz, the odometry's
yaw rate, from the IMU on a robot that fuses it) and, when the log has an IMU topic, its yaw rate as a fourth
channel; both sides are averaged over ``bin_s`` bins (the simulated Mecanum contact makes instantaneous rates jitter,
and encoder odometry averages too), divided per channel by the measured spread. The simulated wheel targets are the
logged commands through the command layer in front (``bigcbf.sim.firmware.ImperfectionLayer``: the latency, bias
and wheel limits of the given robot profile, gain I, no noise) and the robot's Mecanum inverse kinematics, as
``SimWorld`` drives them; the rollout is ``mujoco.sysid.sysid_rollout`` (mujoco.rollout), the fit
``mujoco.sysid.optimize`` (scipy's bounded least squares, finite differences with a relative step: the contact
dynamics are not smooth at the step MuJoCo's own default would take).

Intervals: the residuals are autocorrelated (a transient error lasts several bins), so the iid intervals of
``mujoco.sysid.calculate_intervals`` are too narrow. The stated intervals come from a moving-block bootstrap over
time blocks of ``block_s`` seconds, linearised at the optimum: each replicate draws blocks of (Jacobian rows,
residuals) with replacement and takes the Gauss-Newton step of the resampled problem, theta* = theta_hat -
(J*' J*)^-1 J*' r*; the interval is the replicates' central ``level`` percentile range. Identifiability: a parameter
is identified when sysid's interval is finite (the Jacobian's near-null directions give infinite ones), the
bootstrap half-width is at most ``max_rel_width`` of the value, and the estimate is not at a bound. A parameter the
log does not identify is reported as such, frozen at the model's own value and the others refitted without it; it
is never guessed.

The wheel-speed cap: the command layer calibrated on the log reads a cap on the wheels' rim speed as a firmware
limit, but a damped wheel at its servo's torque limit is capped by the model's own physics. :func:`fit_behind` fits
the model behind the command layer with and without the cap and keeps the smaller residual (docs/twin.md).

Every MuJoCo call of the fit (the MjSpec and its parameters' modifiers, the rollout, the optimizer, the iid
intervals, the check of a written robot folder) is in ``bigcbf.sim.sysid`` (the sim layer: "MuJoCo only in sim");
this module works on numpy arrays, plain values and that module's opaque handles, and imports no MuJoCo itself.
"""
from __future__ import annotations

import math
import re
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from bigcbf.errors import UserError
from bigcbf.params.checks import check_field_ranges, ranged
from bigcbf.params.robot import RobotProfile

#: the fitted parameters: name, unit, meaning (the report's lines)
PARAMS = (("wheel_kv", "N m s/rad", "wheel velocity actuator gain"),
          ("wheel_damping", "N m s/rad", "wheel joint damping"),
          ("floor_friction", "-", "roller/floor sliding friction"),
          ("base_mass", "kg", "chassis mass"))
PARAMS_NAMES = tuple(n for n, _, _ in PARAMS)
CHANNELS = ("vx", "vy", "wz", "imu wz")
#: the smallest per-channel scale of the residual [m/s, m/s, rad/s, rad/s]: an axis the log barely drives (a
#: differential robot's vy) must not be blown up to the others' weight
MIN_SCALE = 0.05
#: identified only when the difference columns over two disjoint pairs of steps correlate at least this much
MIN_REPRODUCIBLE = 0.5
#: coarse_start's box: this far from the start in each fit coordinate (log: a factor of 2; damping: 2 units)
COARSE_HALF = 0.7
#: how far a frozen (not identified) parameter may be from the model's own value, in fit coordinates (_refit)
NUISANCE_HALF = 0.7
#: the damping's coordinate unit, as a fraction of the nominal kv (parameters())
DAMPING_UNIT = 0.1


@dataclass(frozen=True)
class ModelFitOptions:
    bin_s: float = ranged(1.0, 0.02, 5.0)            # residual bins [s]
    max_iters: int = ranged(20, 1, 200)              # least-squares function evaluations (Jacobians not counted)
    diff_step: float = ranged(0.2, 1e-4, 1.0)        # finite-difference step in the log of each parameter [-]
    block_s: float = ranged(4.0, 0.2, 600.0)         # bootstrap time blocks [s]
    n_boot: int = ranged(400, 20, 100000)            # bootstrap replicates
    level: float = ranged(0.9, 0.5, 0.999)           # the intervals' stated coverage
    max_rel_width: float = ranged(0.25, 0.01, 10.0)  # identified: bootstrap half-width <= this x the value
    t_end_s: float | None = ranged(None, 0.0, 1e7, lo_open=True)  # fit up to this time after the first command
    seed: int = ranged(0, 0, 2 ** 31)
    starts: int = ranged(12, 0, 1000)                # coarse_start's points before the local fit

    def __post_init__(self):
        check_field_ranges(self)


@dataclass
class ModelFit:
    """The fitted parameters (module docstring), their intervals and whether the log identifies each."""
    robot: str
    names: list[str]
    nominal: np.ndarray
    value: np.ndarray               # fitted where identified, the model's own value where not
    lo: np.ndarray                  # bootstrap interval (nan where not identified)
    hi: np.ndarray
    iid_halfwidth: np.ndarray       # mujoco.sysid.calculate_intervals' half-width (iid residuals), at the same
    #                                 level, relative to the value
    identified: np.ndarray
    reasons: list[str]              # why each is (not) identified
    level: float
    channels: list[str]
    rms_nominal: np.ndarray         # per channel, the binned residual RMS of the model's own parameters
    rms_fit: np.ndarray             # ... and of the fitted ones
    front: RobotProfile             # the command layer in front
    log_s: float                    # seconds of log fitted
    cpu_s: float                    # CPU time of the fit (rollouts, optimisation, bootstrap)
    evaluations: int
    notes: list[str] = field(default_factory=list)
    cost: float = math.nan          # the final residual's mean square, over the channel scales

    @property
    def cpu_per_log_minute(self) -> float:
        return self.cpu_s / max(self.log_s / 60.0, 1e-9)

    def value_of(self, name: str) -> float:
        return float(self.value[self.names.index(name)])

    def to_json(self) -> dict:
        from .calibrate import jsonable
        return jsonable({
            "robot": self.robot, "level": self.level, "log_s": self.log_s, "cpu_s": self.cpu_s,
            "cpu_s_per_log_minute": self.cpu_per_log_minute, "evaluations": self.evaluations,
            "parameters": {n: {"nominal": float(self.nominal[i]), "value": float(self.value[i]),
                               "interval": [float(self.lo[i]), float(self.hi[i])],
                               "iid_halfwidth": float(self.iid_halfwidth[i]),
                               "identified": bool(self.identified[i]), "why": self.reasons[i]}
                           for i, n in enumerate(self.names)},
            "residual_rms": {"channels": self.channels, "nominal": self.rms_nominal.tolist(),
                             "fitted": self.rms_fit.tolist()}, "cost": self.cost,
            "front": {"latency_s": self.front.latency_s, "bias": list(self.front.bias),
                      "wheel_speed_max_mps": self.front.wheel_speed_max_mps,
                      "wheel_accel_max_mps2": self.front.wheel_accel_max_mps2,
                      "wheel_yaw_lever_m": self.front.wheel_yaw_lever_m},
            "notes": self.notes})

    def summary_lines(self) -> list[str]:
        units = {n: u for n, u, _ in PARAMS}
        out = [f"model fit (mujoco.sysid) of {self.robot} on {self.log_s:.1f} s of log, behind the command layer "
               f"(latency {self.front.latency_s:.3f} s): {self.evaluations} rollouts, {self.cpu_s:.1f} s CPU "
               f"({self.cpu_per_log_minute:.1f} s per minute of log); {self.level:.0%} block-bootstrap intervals"]
        for i, n in enumerate(self.names):
            if self.identified[i]:
                out.append(f"  {n:15s} {self.value[i]:.4g} {units[n]} [{self.lo[i]:.4g}, {self.hi[i]:.4g}] "
                           f"(model's own {self.nominal[i]:.4g})")
            else:
                out.append(f"  {n:15s} not identified: {self.reasons[i]}; kept at the model's own "
                           f"{self.nominal[i]:.4g} {units[n]}")
        out.append("  residual RMS per channel (" + ", ".join(self.channels) + "): model's own "
                   + ", ".join(f"{x:.4f}" for x in self.rms_nominal) + "; fitted "
                   + ", ".join(f"{x:.4f}" for x in self.rms_fit))
        return out + [f"  note: {n}" for n in self.notes]


# --- the model and its parameters ------------------------------------------------------------------------------
def _sim():
    """``bigcbf.sim.sysid``, the fit's MuJoCo side (loaded on first use: importing the twin loads no MuJoCo)."""
    from bigcbf.sim import sysid as sim_sysid
    return sim_sysid


def require_sysid():
    """``mujoco.sysid``, or one line saying how to install it (its optional dependencies missing, the package
    imports empty)."""
    sysid = _sim().load_sysid()
    if sysid is None:
        raise UserError("the model fit needs MuJoCo's system identification (mujoco >= 4 with its sysid extra): "
                        "pip install 'bigcbf[sysid]'")
    return sysid


def base_spec(robot_name: str):
    """The robot's scene (robot + floor) as an MjSpec with a velocity sensor on each wheel joint
    (``bigcbf.sim.sysid.base_spec``; an opaque handle here)."""
    return _sim().base_spec(robot_name)


def physical(name: str, x, kv_nominal: float):
    """The physical value of parameter ``name`` at fit coordinate ``x`` (parameters())."""
    return np.asarray(x, float) * DAMPING_UNIT * kv_nominal if name == "wheel_damping" else np.exp(x)


def coordinates(names, values, kv_nominal: float) -> np.ndarray:
    """The fit coordinates of physical ``values`` (the inverse of :func:`physical`)."""
    return np.array([v / (DAMPING_UNIT * kv_nominal) if n == "wheel_damping" else math.log(v)
                     for n, v in zip(names, values)])


def rel_halfwidth(name: str, x, half) -> np.ndarray:
    """A half-width ``half`` in fit coordinates at ``x`` as a fraction of the physical value."""
    x, half = np.asarray(x, float), np.asarray(half, float)
    return half / np.maximum(np.abs(x), 1e-12) if name == "wheel_damping" else np.expm1(half)


def parameters(robot_name: str):
    """The ``mujoco.sysid.ParameterDict`` of the fitted parameters, nominal = the model's own values, with their
    MjSpec modifiers and bounds, in the fit's coordinates (``Parameter.value``; :func:`physical` gives the value):
    the gain, friction and mass act by ratios, so their coordinate is the natural log (the finite-difference step
    and the intervals are relative); the damping acts through the steady-state gain kv / (kv + damping), nearly
    linear in it and flat in its log near a small value, so its coordinate is damping / (DAMPING_UNIT kv) (1: about
    a 9 % loss of wheel speed), from 0."""
    sim = _sim()
    v = sim.nominal_values(robot_name)
    kv, damping, friction, mass = v["wheel_kv"], v["wheel_damping"], v["floor_friction"], v["base_mass"]
    ln = math.log
    rows = [("wheel_kv", ln(kv), ln(0.1 * kv), ln(10 * kv)),
            ("wheel_damping", damping / (DAMPING_UNIT * kv), 0.0, 4.0),
            ("floor_friction", ln(friction), ln(0.1), ln(3.0)),
            ("base_mass", ln(mass), ln(0.3 * mass), ln(3.0 * mass))]
    return sim.parameter_dict(robot_name, rows, lambda name, x: physical(name, x, kv))


# --- the signals -------------------------------------------------------------------------------------------------
def wheel_targets(cmd_t: np.ndarray, cmd_u: np.ndarray, front: RobotProfile, kin, times: np.ndarray) -> np.ndarray:
    """The wheel speed targets (len(times), 4) [rad/s] at ``times`` (relative to the first command): the commands
    through the command layer in front (its latency, bias and wheel limits; no noise) and the inverse kinematics,
    as SimWorld.step drives the actuators."""
    from bigcbf.sim.firmware import ImperfectionLayer
    quiet = replace(front, latency_jitter_s=0.0, residual_max=(0.0, 0.0, 0.0), slip_max=0.0,
                    gain=((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)))
    imp = ImperfectionLayer(quiet, np.random.default_rng(0), lever_m=kin.half_wheelbase_m + kin.half_track_m)
    rel = np.asarray(cmd_t, float) - float(cmd_t[0])
    out = np.zeros((len(times), 4))
    k = 0
    hold = float(times[1] - times[0]) if len(times) > 1 else 0.0
    for i, t in enumerate(times):
        while k < len(rel) and rel[k] <= t + 1e-12:
            imp.submit(float(rel[k]), cmd_u[k])
            k += 1
        twist = imp.at(float(t))
        # the limiter's mean over each control interval, as SimWorld.step holds its mean over each physics block
        target = imp.limiter.update(float(t), twist, hold) if imp.limiter is not None else twist
        out[i] = kin.inverse(target)
    return out


def binned(t: np.ndarray, y: np.ndarray, edges: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per bin [edges[k], edges[k+1]) the mean of the rows of y whose t falls in it; and which bins have any."""
    k = np.searchsorted(edges, t, side="right") - 1
    ok = (k >= 0) & (k < len(edges) - 1)
    n = np.bincount(k[ok], minlength=len(edges) - 1)
    out = np.full((len(edges) - 1, y.shape[1]), np.nan)
    for j in range(y.shape[1]):
        s = np.bincount(k[ok], weights=y[ok, j], minlength=len(edges) - 1)
        out[:, j] = np.where(n > 0, s / np.maximum(n, 1), np.nan)
    return out, n > 0


def read_imu_yaw_rate(path, t0: float) -> tuple[np.ndarray, np.ndarray] | None:
    """The log's IMU yaw rate (times relative to ``t0``, rates), or None when it has no IMU topic."""
    from bigcbf.logio import find_topic, open_log
    from bigcbf.logio.topics import IMU
    with open_log(path) as log:
        topic = find_topic(log, IMU, required=False)
        if topic is None:
            return None
        rows = [(t, float(msg.angular_velocity.z)) for _, t, msg in log.messages([topic])]
    if len(rows) < 2:
        return None
    a = np.array(rows, float)
    return a[:, 0] - t0, a[:, 1]


@dataclass
class Problem:
    """One fit: the measured bins and everything a rollout needs."""
    robot: str
    spec: object
    kin: object
    control: object                 # sysid TimeSeries of the wheel targets at the physics step
    initial_state: np.ndarray
    edges: np.ndarray               # bin edges [s after the first command]
    measured: np.ndarray            # (bins, channels), nan-free rows only
    keep: np.ndarray                # the bins used
    scale: np.ndarray               # per channel
    channels: list[str]
    evaluations: int = 0


def problem(data, front: RobotProfile, robot_name: str, opt: ModelFitOptions, imu=None) -> Problem:
    """The fit's measured bins (odometry twist, IMU yaw rate when given: (t, rate) relative to the first command)
    and the wheel targets over the fitted span."""
    from bigcbf import robots
    sim = _sim()
    R = robots.robot(robot_name)
    spec, model, dt = sim.compile_base(robot_name)
    t0 = float(data.cmd.t[0])
    span = float(data.odom.t[-1] - t0) if opt.t_end_s is None else min(opt.t_end_s, float(data.odom.t[-1] - t0))
    n_bins = int(span // opt.bin_s)
    if n_bins < 10:
        raise UserError(f"the model fit needs at least {10 * opt.bin_s:g} s of odometry after the first command, the "
                        f"log has {span:.3g} s", file=str(data.path))
    edges = np.arange(n_bins + 1) * opt.bin_s
    ts = data.odom.t - t0
    meas, have = binned(ts, data.odom.twist, edges)
    channels = list(CHANNELS[:3])
    if imu is not None:
        m_imu, h_imu = binned(imu[0], imu[1][:, None], edges)
        meas, have = np.column_stack([meas, m_imu]), have & h_imu
        channels.append(CHANNELS[3])
    times = np.arange(int(round(span / dt))) * dt
    ctrl = wheel_targets(data.cmd.t, data.cmd.u, front, R.kinematics, times)
    control, state = sim.rollout_inputs(model, R.actuators, times, ctrl)
    scale = np.maximum(np.nanstd(meas[have], axis=0), MIN_SCALE)
    return Problem(robot_name, spec, R.kinematics, control, state, edges, meas[have], have, scale, channels)


def simulate_bins(pb: Problem, params) -> np.ndarray:
    """Roll the model with ``params`` out over the fitted span (``mujoco.sysid.sysid_rollout``) and bin its
    odometry twist (wheel speeds through the forward kinematics; yaw rate from the IMU gyro) like the log's."""
    times, w, gyro = _sim().rollout_wheels_gyro(pb.spec, params, pb.control, pb.initial_state,
                                                robots_wheels(pb.robot))
    twist = (np.linalg.pinv(pb.kin.jacobian) @ w.T).T * np.asarray(pb.kin.effective_scale)
    twist[:, 2] = gyro
    sim, _ = binned(times, twist, pb.edges)
    sim = sim[pb.keep]
    if len(pb.channels) == 4:
        sim = np.column_stack([sim, sim[:, 2]])
    pb.evaluations += 1
    return sim


def ensemble_bins(pb: Problem, params, angles: np.ndarray) -> np.ndarray:
    """:func:`simulate_bins` once per row of ``angles`` (the wheels turned by that much at the start,
    ``bigcbf.sim.sysid.wheel_phase_states``): (members, bins, channels). The simulated Mecanum contact is chaotic in
    yaw (module docstring of ``reproducible_columns``): one rollout is one draw of where each roller meets the floor,
    and the members' mean is the model's expected response, which a parameter must move to be identifiable
    (``scripts/twin_identifiability.py``)."""
    own = pb.initial_state
    try:
        out = []
        for state in _sim().wheel_phase_states(pb.spec, own, robots_wheels(pb.robot), angles):
            pb.initial_state = state
            out.append(simulate_bins(pb, params))
        return np.array(out)
    finally:
        pb.initial_state = own


def robots_wheels(name: str) -> tuple[str, ...]:
    from bigcbf import robots
    return robots.robot(name).wheels


def residual_fn(pb: Problem):
    """The residual in ``mujoco.sysid.optimize``'s form: ``(x, params) -> ([r], None, None)``, r the binned
    simulated minus measured signals over the channel scales, bin-major (x a batch of columns: r one column each)."""
    def one(x, params):
        params.update_from_vector(x)
        r = (simulate_bins(pb, params) - pb.measured) / pb.scale
        return np.nan_to_num(r, nan=0.0).ravel()

    def fn(x, params, **_):
        x = np.asarray(x, float)
        if x.ndim == 2:             # a batch of columns (mujoco.minimize.jacobian_fd): (n_res, n_columns)
            return [np.column_stack([one(x[:, k], params) for k in range(x.shape[1])])], None, None
        return [one(x, params)], None, None
    return fn


# --- the fit, its intervals and what the log identifies ----------------------------------------------------------
def block_bootstrap(J: np.ndarray, r: np.ndarray, n_ch: int, block_bins: int, n_boot: int, level: float,
                    rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Moving-block bootstrap linearised at the optimum (module docstring): the ``level`` percentile range of the
    replicates' Gauss-Newton steps, centred on the full sample's own step (a fit stopped short of a smooth minimum
    keeps a step of its own), per parameter (lo, hi offsets). Rows of J and r are bin-major (n_ch per bin)."""
    n_bins = len(r) // n_ch
    b = max(1, min(block_bins, n_bins))
    n_blocks = int(math.ceil(n_bins / b))
    full = -np.linalg.lstsq(J, r, rcond=1e-10)[0]
    steps = np.zeros((n_boot, J.shape[1]))
    for k in range(n_boot):
        starts = rng.integers(0, n_bins - b + 1, n_blocks)
        rows = (starts[:, None] * n_ch + np.arange(b * n_ch)[None, :]).ravel()
        steps[k] = -np.linalg.lstsq(J[rows], r[rows], rcond=1e-10)[0] - full
    a = (1 - level) / 2
    return np.quantile(steps, a, axis=0), np.quantile(steps, 1 - a, axis=0)


def reproducible_columns(pb: Problem, params, r: np.ndarray, h: float, only=None):
    """The Jacobian at the fit and, per parameter, whether its effect is reproducible: two difference columns that
    share no simulated point, (r(x+h) - r(x-h)) / 2h and (r(x+2h) - r(x-2h)) / 4h (near the lower bound the
    one-sided (r(x+h) - r(x)) / h and (r(x+3h) - r(x+h)) / 2h), and their correlation. A parameter whose effect on
    the measured signals is information gives nearly the same column twice; one whose differences are the contact
    dynamics' chaos (the simulated yaw rate jumps with any change of the model, by about 0.06 rad/s in 1-s bins)
    gives two unrelated ones. Returns (the mean of the two columns, the correlations), for the parameters ``only``
    (indices; None: all; the others' columns are left zero)."""
    fn = residual_fn(pb)
    x = params.as_vector()
    lo, _ = params.get_bounds()
    J, corr = np.zeros((len(r), len(x))), np.zeros(len(x))

    def at(i, d):
        xs = x.copy()
        xs[i] += d
        return fn(xs, params)[0][0]

    for i in range(len(x)) if only is None else only:
        if x[i] - 2 * h >= lo[i]:
            a = (at(i, h) - at(i, -h)) / (2 * h)
            b = (at(i, 2 * h) - at(i, -2 * h)) / (4 * h)
        else:
            rh = at(i, h)
            a, b = (rh - r) / h, (at(i, 3 * h) - rh) / (2 * h)
        J[:, i] = 0.5 * (a + b)
        a, b = a - a.mean(), b - b.mean()
        corr[i] = float(a @ b / max(np.sqrt((a @ a) * (b @ b)), 1e-300))
    params.update_from_vector(x)
    return J, corr


def coarse_start(pb: Problem, params, opt: ModelFitOptions) -> None:
    """Set ``params`` to the best of its current value and ``opt.starts`` Latin-hypercube points of its search box
    within COARSE_HALF of the current value in each coordinate (the contact dynamics make the cost rugged at the
    scale of a finite-difference step: a local fit from the model's own values alone stops in the nearest dip)."""
    if opt.starts == 0:
        return
    from scipy.stats import qmc
    fn = residual_fn(pb)
    lo, hi = params.get_bounds()
    x0 = params.as_vector()
    lo, hi = np.maximum(lo, x0 - COARSE_HALF), np.minimum(hi, x0 + COARSE_HALF)
    pts = qmc.scale(qmc.LatinHypercube(d=len(lo), seed=opt.seed).random(opt.starts), lo, hi)
    best, cost = x0, float(np.sum(fn(x0, params)[0][0] ** 2))
    for x in pts:
        c = float(np.sum(fn(x, params)[0][0] ** 2))
        if c < cost:
            best, cost = x, c
    params.update_from_vector(best)


def _optimize(pb: Problem, params, opt: ModelFitOptions, coarse: bool = True):
    """One bounded least-squares fit with mujoco.sysid.optimize (after :func:`coarse_start` when ``coarse``);
    (fitted ParameterDict, result, residual)."""
    fn = residual_fn(pb)
    if coarse:
        coarse_start(pb, params, opt)
    fitted, res = _sim().optimize(params, fn, opt.max_iters, opt.diff_step)
    r = fn(fitted.as_vector(), fitted)[0][0]
    return fitted, res, r


def _judge(names, x, lo_b, hi_b, lo, hi, iid, corr, opt: ModelFitOptions) -> tuple[np.ndarray, list[str]]:
    """Per parameter (in the fit's coordinates): identified?, and why (module docstring's tests)."""
    ok, why = np.zeros(len(names), bool), []
    for i in range(len(names)):
        rel = float(rel_halfwidth(names[i], x[i], 0.5 * (hi[i] - lo[i])))   # relative to the value
        if not np.isfinite(iid[i]):
            why.append("the measured signals do not depend on it (mujoco.sysid: infinite interval, a null direction "
                       "of the Jacobian)")
        elif corr[i] < MIN_REPRODUCIBLE:
            why.append(f"its effect on the measured signals is not reproducible (differences over two disjoint "
                       f"pairs of steps correlate {corr[i]:.2f}, below {MIN_REPRODUCIBLE}): what changes is the "
                       "contact dynamics' chaos, not information")
        elif min(x[i] - lo_b[i], hi_b[i] - x[i]) <= 0.01 * (hi_b[i] - lo_b[i]):
            why.append("the fit ran to a bound of its search range")
        elif rel > opt.max_rel_width:
            why.append(f"its {opt.level:.0%} interval is +-{rel:.0%} of the value (identified: at most "
                       f"+-{opt.max_rel_width:.0%})")
        else:
            ok[i] = True
            why.append(f"+-{rel:.1%} of the value at {opt.level:.0%}; differences reproducible ({corr[i]:.2f})")
    return ok, why


def _intervals(pb: Problem, params, res, r, opt: ModelFitOptions):
    """Bootstrap (lo, hi), sysid's iid half-width and the columns' reproducibility for the non-frozen parameters
    of ``params`` (fit coordinates)."""
    J, corr = reproducible_columns(pb, params, r, opt.diff_step)
    x = params.as_vector()
    iid = _sim().iid_halfwidth(r, J, opt.level)
    block_bins = max(1, int(round(opt.block_s / opt.bin_s)))
    d_lo, d_hi = block_bootstrap(J, r, len(pb.channels), block_bins, opt.n_boot, opt.level,
                                 np.random.default_rng(opt.seed))
    lo_b, hi_b = params.get_bounds()
    return np.clip(x + d_lo, lo_b, hi_b), np.clip(x + d_hi, lo_b, hi_b), iid, corr, J


def fit_model(data, front: RobotProfile, robot_name: str = "rosmaster_x3",
              opt: ModelFitOptions = ModelFitOptions(), imu=None) -> ModelFit:
    """Fit the model's parameters (module docstring) to a log (LogData on its analysis time base) behind the
    command layer ``front``; ``imu``: the IMU yaw rate (t after the first command, rate) or None."""
    c0 = time.process_time()
    require_sysid()
    pb = problem(data, front, robot_name, opt, imu)
    params = parameters(robot_name)
    names = params.keys()
    nominal = params.as_nominal_vector()
    fn = residual_fn(pb)
    r0 = fn(nominal, params.copy())[0][0]
    fitted, res, r = _optimize(pb, params, opt)
    lo_b, hi_b = params.get_bounds()
    x = fitted.as_vector()
    lo, hi, iid, corr, _ = _intervals(pb, fitted, res, r, opt)
    ok, why = _judge(names, x, lo_b, hi_b, lo, hi, iid, corr, opt)
    notes = []
    if ok.any() and not ok.all():        # refit what the log identifies, the rest frozen at the model's own
        x, lo, hi, iid, note = _refit(pb, robot_name, x, ok, why, opt)
        notes.append(note)
    elif not ok.any():
        x = nominal.copy()
        notes.append("the log identifies none of the model's parameters: the model is kept as it is")
    x = np.where(ok, x, nominal)
    lo, hi = np.where(ok, lo, np.nan), np.where(ok, hi, np.nan)
    final = parameters(robot_name)
    final.update_from_vector(x)
    rms = lambda rr: np.sqrt(np.mean((rr.reshape(-1, len(pb.channels)) * pb.scale) ** 2, axis=0))   # noqa: E731
    r_fin = fn(x, final)[0][0]
    kv = float(np.exp(nominal[0]))
    ph = lambda v: np.array([physical(n, v[i], kv) for i, n in enumerate(names)])      # noqa: E731
    iid = np.array([rel_halfwidth(n, x[i], iid[i]) for i, n in enumerate(names)])
    return ModelFit(robot_name, names, ph(nominal), ph(x), ph(lo), ph(hi), iid, ok, why,
                    opt.level, pb.channels, rms(r0), rms(r_fin), front, float(pb.edges[-1]),
                    time.process_time() - c0, pb.evaluations, notes, float(np.mean(r_fin ** 2)))


def _refit(pb: Problem, robot_name: str, x: np.ndarray, ok: np.ndarray, why: list[str], opt: ModelFitOptions):
    """Refit the identified parameters with the others frozen at the model's own values; their intervals widened
    by what the frozen ones could shift them (below); ``ok`` and ``why`` updated in place. Returns (x, lo, hi,
    iid half-width, note), all in fit coordinates.

    A frozen parameter is not known to be the model's own value: a robot whose chassis is heavier than the
    model's moves the wheel damping the fit finds. Each identified parameter's interval is therefore widened on both
    sides by sum_f |S_if| w_f, S = -(J_id' J_id)^-1 J_id' J_f the linearised shift of the identified parameters per
    unit of frozen parameter f (its columns from :func:`reproducible_columns` at the refit), w_f = NUISANCE_HALF
    (the frozen parameters are taken as known within a factor of 2, the damping within 2 units)."""
    names = parameters(robot_name).keys()
    again = parameters(robot_name)
    nominal = again.as_nominal_vector()
    for i, n in enumerate(names):
        if ok[i]:
            again[n].update_from_vector(np.array([x[i]]))
        else:
            again[n].frozen = True
    lo_b, hi_b = again.get_bounds()
    refit, res, r = _optimize(pb, again, opt, coarse=False)
    sub = [i for i in range(len(names)) if ok[i]]
    frozen = [i for i in range(len(names)) if not ok[i]]
    lo2, hi2, iid2, corr2, J_id = _intervals(pb, refit, res, r, opt)
    xs = refit.as_vector()
    full = parameters(robot_name)
    x_full = nominal.copy()
    x_full[sub] = xs
    full.update_from_vector(x_full)
    J_f = reproducible_columns(pb, full, r, opt.diff_step, only=frozen)[0][:, frozen]
    shift = np.abs(np.linalg.lstsq(J_id, J_f, rcond=1e-10)[0]) @ np.full(len(frozen), NUISANCE_HALF)
    lo2, hi2 = np.maximum(lo2 - shift, lo_b), np.minimum(hi2 + shift, hi_b)
    ok2, why2 = _judge([names[i] for i in sub], xs, lo_b, hi_b, lo2, hi2, iid2, corr2, opt)
    x, lo, hi, iid = nominal.copy(), np.full(len(names), np.nan), np.full(len(names), np.nan), np.full(len(names),
                                                                                                      np.inf)
    x[sub], lo[sub], hi[sub], iid[sub] = xs, lo2, hi2, iid2
    for k, i in enumerate(sub):
        ok[i], why[i] = ok2[k], why2[k]
    return x, lo, hi, iid, ("refitted with " + ", ".join(names[i] for i in frozen) + " frozen at the model's own "
                            "value; the intervals include what those could shift within a factor of 2")


# --- the fitted robot folder ---------------------------------------------------------------------------------------
def _sub_attr(text: str, tag_re: str, attr: str, value: str, what: str, path) -> str:
    """``text`` with attribute ``attr`` of the first element matching ``tag_re`` set to ``value``."""
    m = re.search(tag_re, text)
    if m is None:
        raise UserError(f"cannot write the fitted {what}: no element matching {tag_re!r}", file=str(path))
    elem = m.group(0)
    new = re.sub(rf'\b{attr}="[^"]*"', f'{attr}="{value}"', elem, count=1) if re.search(rf'\b{attr}="', elem) \
        else elem.replace("/>", f' {attr}="{value}"/>', 1)
    return text[:m.start()] + new + text[m.end():]


def write_robot_folder(fit: ModelFit, out: str | Path) -> list[Path]:
    """Write the fitted model as a robot folder ``out`` (``bigcbf/robots.py``: ``<name>.xml`` and ``scene.xml``,
    ``profiles/<name>.toml`` the command layer in front as a robot profile, ``README.md``, ``fit.json``, and sysid's
    ``params_x_hat.yaml``); ``<name>`` is the folder's name. The base robot's MJCF text is kept, with the fitted
    values of the identified parameters written in (checked by compiling the folder and reading them back)."""
    import json

    from bigcbf import robots
    from bigcbf.outputs import write_text
    from bigcbf.params.toml_io import save
    out = Path(out)
    name = out.resolve().name
    R = robots.robot(fit.robot)
    xml, scene = R.xml.read_text(), R.scene_xml.read_text()
    v = {n: fit.value_of(n) for n in fit.names}
    g6 = lambda x: f"{x:.6g}"      # noqa: E731
    xml = _sub_attr(xml, r'<velocity\b[^>]*\bkv="[^"]*"[^>]*/>', "kv", g6(v["wheel_kv"]), "wheel gain", R.xml)
    xml = _sub_attr(xml, r'<default class="wheel">\s*<joint\b[^>]*/>', "damping", g6(v["wheel_damping"]),
                    "wheel damping", R.xml)
    xml = _sub_attr(xml, r'<geom name="chassis"[^>]*/>', "mass", g6(v["base_mass"]), "chassis mass", R.xml)
    xml = re.sub(r'<mujoco model="[^"]*"', f'<mujoco model="{name}"', xml, count=1)
    scene = scene.replace(f'file="{R.xml.name}"', f'file="{name}.xml"')
    fr = re.search(r'<geom name="floor"[^>]*/>', scene)
    if fr is None or 'friction="' not in fr.group(0):
        raise UserError("cannot write the fitted floor friction: no floor geom with a friction", file=str(R.scene_xml))
    rest = fr.group(0).split('friction="')[1].split('"')[0].split()[1:]
    scene = _sub_attr(scene, r'<geom name="floor"[^>]*/>', "friction", " ".join([g6(v["floor_friction"]), *rest]),
                      "floor friction", R.scene_xml)
    written = [write_text(out / f"{name}.xml", xml, "robot MJCF"), write_text(out / "scene.xml", scene, "scene")]
    save(fit.front, out / "profiles" / f"{name}.toml",
         header=f"The command layer in front of the fitted model {name} (bigcbf calibrate --model).")
    written.append(out / "profiles" / f"{name}.toml")
    written.append(write_text(out / "fit.json", json.dumps(fit.to_json(), indent=1), "fit"))
    written.append(write_text(out / "README.md", readme(fit, name), "README"))
    pd = parameters(fit.robot)
    pd.update_from_vector(coordinates(fit.names, fit.value, fit.nominal[0]))    # sysid's own record of the fit
    pd.save_to_disk(out / "params_x_hat.yaml")
    written.append(out / "params_x_hat.yaml")
    check_written(out, fit)
    return written


def check_written(out: Path, fit: ModelFit) -> None:
    """Compile the written folder as a robot and compare its parameters with the fit's (a text edit that missed
    would otherwise pass silently)."""
    from bigcbf import robots
    R = robots.robot(str(out))
    c = _sim().compiled_fit_values(R.scene_xml, robots.robot(fit.robot).scene_xml, R.actuators[0], R.wheels[0])
    got = {"wheel_kv": c["wheel_kv"], "wheel_damping": c["wheel_damping"], "floor_friction": c["floor_friction"],
           "base_mass": fit.nominal[fit.names.index("base_mass")] + c["base_link_mass"] - c["base_mass_of_base"]}
    for n in got:
        if not np.isclose(got[n], fit.value_of(n), rtol=1e-4, atol=1e-9):
            raise UserError(f"the written model has {n} = {got[n]:.6g}, the fit {fit.value_of(n):.6g}",
                            file=str(out))


def readme(fit: ModelFit, name: str) -> str:
    lines = [f"# {name}: {fit.robot} with its physics fitted to a log", "",
             "Written by `bigcbf calibrate LOG --model DIR` (twin/model_fit.py: mujoco.sysid behind the command layer).",
             "Replay it with `bigcbf replay LOG --robot DIR`; run it in a scenario with `[robot] model = \"DIR\"` and "
             f"`--robot-profile DIR/profiles/{name}.toml` (the command layer in front).", "", "```"]
    lines += fit.summary_lines() + ["```", ""]
    return "\n".join(lines)


def model_with(robot_name: str, values: dict, front: RobotProfile = RobotProfile()) -> ModelFit:
    """A ModelFit holding given parameter values (the others the model's own), e.g. a hidden model of a recovery
    check, for :func:`write_robot_folder`."""
    pd = parameters(robot_name)
    names, nominal = pd.keys(), pd.as_nominal_vector()
    unknown = set(values) - set(names)
    if unknown:
        raise ValueError(f"unknown model parameters {sorted(unknown)}; known: {names}")
    kv = float(np.exp(nominal[0]))
    x = np.array([float(values.get(n, physical(n, nominal[i], kv))) for i, n in enumerate(names)])
    n = len(names)
    return ModelFit(robot_name, names, np.array([physical(k, nominal[i], kv) for i, k in enumerate(names)]), x, x.copy(), x.copy(), np.zeros(n), np.ones(n, bool),
                    ["given"] * n, 1.0, [], np.zeros(0), np.zeros(0), front, 0.0, 0.0, 0)


# --- the fit of a log, behind its calibrated command layer ---------------------------------------------------------
IDENTITY = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))


def front_of(profile: RobotProfile) -> RobotProfile:
    """The command layer in front of the fitted model: the calibrated profile's latency, bias and wheel limits;
    gain I (the model's physics now answers for the gain) and the scene's own floor (the fit's friction)."""
    return replace(profile, gain=IDENTITY, floor_friction=None)


def _imu(raw, t0: float):
    """The log's IMU yaw rate when the log is a file with an IMU topic (else None)."""
    try:
        return read_imu_yaw_rate(raw.path, t0) if Path(raw.path).exists() else None
    except UserError:
        return None


def fit_behind(data, front: RobotProfile, robot_name: str = "rosmaster_x3",
               opt: ModelFitOptions = ModelFitOptions(), imu=None) -> ModelFit:
    """:func:`fit_model` behind the command layer ``front``, with the wheel-speed cap explained by whichever of the
    two the log prefers. A cap the command layer reads from the log (``wheel_speed_max_mps``) may be the firmware's
    clamp or the model's own physics: the wheel servos' torque limit against the wheel damping holds a wheel below
    torque limit / damping (``scripts/twin_identifiability.py``; docs/twin.md). With a cap in front, the model is
    fitted twice, behind the command layer as read and behind it without the cap, and the fit whose residual is
    smaller is kept (the one without the cap on a tie: the physics alone explains it), with a note saying which and
    both residuals; the CPU time counts both fits."""
    fit = fit_model(data, front, robot_name, opt, imu=imu)
    if front.wheel_speed_max_mps is None:
        return fit
    bare = fit_model(data, replace(front, wheel_speed_max_mps=None), robot_name, opt, imu=imu)
    cpu, evals = fit.cpu_s + bare.cpu_s, fit.evaluations + bare.evaluations
    cap = f"{front.wheel_speed_max_mps:.3g} m/s"
    if bare.cost <= fit.cost:
        keep, why = bare, (f"the wheel-speed cap the command layer read ({cap}) is left to the model (its wheels' "
                           f"torque limit and damping): fitted without it the residual is {bare.cost:.4g}, with it "
                           f"{fit.cost:.4g}")
    else:
        keep, why = fit, (f"the command layer's wheel-speed cap ({cap}) kept in front of the model: fitted without "
                          f"it the residual is {bare.cost:.4g}, with it {fit.cost:.4g}")
    keep.cpu_s, keep.evaluations = cpu, evals
    keep.notes.append(why)
    return keep


def fit_log(raw, robot_name: str = "rosmaster_x3", opt: ModelFitOptions = ModelFitOptions(), cal_opt=None,
            t_split: float | None = None) -> ModelFit:
    """``bigcbf calibrate LOG --model``: calibrate the command layer on the log (up to log time ``t_split``) as
    ``bigcbf replay`` maps it onto the model (twin.replay.command_profile), then fit the model behind it."""
    data, front, imu, more = log_front(raw, robot_name, cal_opt, t_split)
    if t_split is not None:
        opt = replace(opt, t_end_s=t_split - float(data.cmd.t[0]))
    fit = fit_behind(data, front, robot_name, opt, imu=imu)
    fit.notes += [n for n in more if "nominal replay" in n]
    return fit


def log_front(raw, robot_name: str = "rosmaster_x3", cal_opt=None, t_split: float | None = None):
    """What :func:`fit_log` fits behind: (the log on its analysis time base, the calibrated command layer in front
    of the model (:func:`front_of`), the log's IMU yaw rate or None, the command layer's notes)."""
    from .calibrate import CalibrationOptions
    from .replay import _checked, _log_model, command_profile, run_profile, scene_for
    cal_opt = cal_opt or CalibrationOptions()
    data, timing, tb_notes, notes = _checked(raw, cal_opt)
    scene = scene_for(data.odom.pose[:, :2], robot_name)
    nominal = run_profile("nominal", data, RobotProfile(), 5.0, scene=scene, period_s=timing.period_s)
    cal, delay_s = _log_model(raw, data, cal_opt, None, t_split, notes)
    if cal is None:
        raise UserError("the model fit needs the command layer in front of it, and the log could not be calibrated: "
                        + "; ".join(n for n in notes if n.startswith("no calibrated replay")), file=str(raw.path))
    prof, _, more = command_profile(data, cal, None, delay_s, nominal, scene, timing.period_s, 5.0, cal_opt, t_split)
    return data, front_of(prof), _imu(raw, float(data.cmd.t[0])), more


def model_run(raw, data, prof: RobotProfile, opt, period_s, t_split, robot_dir=None):
    """The replay's "model" run (twin.replay.replay): the robot folder ``robot_dir`` behind its own command layer
    (``profiles/<name>.toml``), or the model fitted on the log up to ``t_split`` behind the calibrated command layer
    ``prof``; scored from ``t_split``. Returns (run, the fit or None, notes)."""
    import tempfile

    from bigcbf.scenario import load_robot_profile

    from .replay import run_profile, scene_for
    pose = data.odom.pose[:, :2]
    if robot_dir is not None:
        d = Path(robot_dir)
        prof_file = d / "profiles" / f"{d.resolve().name}.toml"
        front = load_robot_profile(prof_file) if prof_file.is_file() else front_of(prof)
        run = run_profile("model", data, front, opt.window_s, scene=scene_for(pose, str(d)), period_s=period_s,
                          t_from=t_split)
        return run, None, [f"model replay: the robot folder {d} behind "
                           + (f"its command layer ({prof_file.name})" if prof_file.is_file() else
                              "this log's calibrated command layer (the folder has no profiles/<name>.toml)")]
    t0 = float(data.cmd.t[0])
    mopt = ModelFitOptions(t_end_s=None if t_split is None else t_split - t0)
    fit = fit_behind(data, front_of(prof), "rosmaster_x3", mopt, imu=_imu(raw, t0))
    with tempfile.TemporaryDirectory(prefix="bigcbf-model-") as tmp:
        d = Path(tmp) / "fitted_model"
        write_robot_folder(fit, d)
        run = run_profile("model", data, fit.front, opt.window_s, scene=scene_for(pose, str(d)), period_s=period_s,
                          t_from=t_split)
    ident = [n for n, ok in zip(fit.names, fit.identified) if ok]
    return run, fit, [f"model replay: mujoco.sysid fit on the first {fit.log_s:.1f} s ("
                      + (", ".join(ident) + " identified" if ident else "no parameter identified") + "; "
                      f"{fit.cpu_s:.0f} s CPU)"]
