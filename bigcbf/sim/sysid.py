"""MuJoCo's side of the model fit (``twin/model_fit.py``, ``bigcbf calibrate LOG --model``): every call into mujoco
and ``mujoco.sysid`` the fit makes, so that the twin works on numpy arrays, plain values and opaque handles only
(DESIGN.md: "sim  MuJoCo only here").

The handles: an MjSpec (:func:`base_spec`, :func:`compile_base`), a compiled MjModel, a ``mujoco.sysid``
``ParameterDict`` (:func:`parameter_dict`; the twin reads and sets it through its own methods: ``keys``,
``as_vector``, ``update_from_vector``, ``get_bounds``, ``save_to_disk``...), and sysid's control ``TimeSeries`` and
initial state (:func:`rollout_inputs`). What the fitted parameters mean, their coordinates and the fit itself are
the twin's (``twin/model_fit.py``'s docstring).
"""
from __future__ import annotations

import contextlib
import io
from pathlib import Path
from typing import Callable

import mujoco
import numpy as np

from bigcbf import robots
from bigcbf.errors import UserError


def load_sysid():
    """``mujoco.sysid``, or None when it cannot be imported or imports empty (its optional dependencies missing:
    the package then has no ``optimize``)."""
    try:
        from mujoco import sysid
    except ImportError:
        sysid = None
    if sysid is None or not hasattr(sysid, "optimize"):
        return None
    return sysid


def base_spec(robot_name: str):
    """The robot's scene (robot + floor) as an MjSpec with a velocity sensor ``<joint>_speed`` on each wheel joint."""
    R = robots.robot(robot_name)
    spec = mujoco.MjSpec.from_file(str(R.scene_xml))
    for j in R.wheels:
        spec.add_sensor(name=f"{j}_speed", type=mujoco.mjtSensor.mjSENS_JOINTVEL, objtype=mujoco.mjtObj.mjOBJ_JOINT,
                        objname=j)
    if spec.geom("floor") is None or spec.geom("chassis") is None:
        raise UserError(f"robot {robot_name!r}: the model fit needs a geom 'floor' in scene.xml and a geom 'chassis'",
                        file=str(R.scene_xml))
    return spec


def nominal_values(robot_name: str) -> dict[str, float]:
    """The model's own values of the fitted parameters (physical units): the first wheel actuator's gain
    ``wheel_kv``, the first wheel joint's ``wheel_damping``, the floor geom's sliding ``floor_friction`` and the
    chassis geom's ``base_mass``."""
    R = robots.robot(robot_name)
    spec = base_spec(robot_name)
    return {"wheel_kv": float(spec.actuator(R.actuators[0]).gainprm[0]),
            "wheel_damping": float(spec.joint(R.wheels[0]).damping[0]),
            "floor_friction": float(spec.geom("floor").friction[0]),
            "base_mass": float(spec.geom("chassis").mass)}


def _modifiers(robot_name: str, value: Callable) -> dict[str, Callable]:
    """Per fitted parameter, its MjSpec modifier ``(spec, parameter) -> None``; ``value(parameter)`` is the physical
    value it writes: the gain on every wheel actuator (gain and its velocity bias alike), the damping on every wheel
    joint, the floor geom's sliding friction, the chassis geom's mass."""
    R = robots.robot(robot_name)

    def set_kv(s, p):
        for a in R.actuators:
            s.actuator(a).gainprm[0] = value(p)
            s.actuator(a).biasprm[2] = -value(p)

    def set_damping(s, p):
        for j in R.wheels:
            s.joint(j).damping[0] = value(p)

    def set_friction(s, p):
        s.geom("floor").friction[0] = value(p)

    def set_mass(s, p):
        s.geom("chassis").mass = value(p)

    return {"wheel_kv": set_kv, "wheel_damping": set_damping, "floor_friction": set_friction, "base_mass": set_mass}


def parameter_dict(robot_name: str, rows, to_physical: Callable[[str, float], float]):
    """A ``mujoco.sysid.ParameterDict`` (an opaque handle) of the parameters ``rows``: (name, nominal, lower bound,
    upper bound) in the fit's coordinates, names from :func:`nominal_values`, in order. Each carries the MjSpec
    modifier of its name, which writes ``to_physical(name, coordinate)`` into the spec."""
    from mujoco import sysid
    mods = _modifiers(robot_name, lambda p: to_physical(p.name, float(p.value[0])))
    pd = sysid.ParameterDict()
    for name, nominal, lo, hi in rows:
        pd.add(sysid.Parameter(name, nominal, lo, hi, modifier=mods[name]))
    return pd


def compile_base(robot_name: str):
    """(:func:`base_spec`, its compiled model, the model's physics timestep [s])."""
    spec = base_spec(robot_name)
    model = spec.compile()
    return spec, model, float(model.opt.timestep)


def rollout_inputs(model, actuators, times: np.ndarray, ctrl: np.ndarray):
    """sysid's control TimeSeries of the actuator targets ``ctrl`` (len(times), len(actuators)) at ``times``, and its
    initial state of ``model`` (the model's initial qpos and qvel after mj_forward): the rollout's inputs."""
    from mujoco import sysid
    control = sysid.TimeSeries.from_control_names(times, ctrl, model, list(actuators))
    d = mujoco.MjData(model)
    mujoco.mj_forward(model, d)
    return control, sysid.create_initial_state(model, d.qpos.copy(), d.qvel.copy())


def wheel_phase_states(spec, initial_state, wheels, angles: np.ndarray) -> list:
    """Copies of sysid's ``initial_state`` of the model of ``spec`` with the wheel joints ``wheels`` turned by
    ``angles`` (rows of len(wheels) angles [rad], added to the state's own): the same robot at the same pose and
    speed, each wheel's rollers meeting the floor at another point of their sweep."""
    from mujoco import sysid
    model = spec.compile()
    d = mujoco.MjData(model)
    mujoco.mj_setState(model, d, np.asarray(initial_state, float), mujoco.mjtState.mjSTATE_FULLPHYSICS)
    adr = [model.jnt_qposadr[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, w)] for w in wheels]
    out = []
    for row in np.atleast_2d(np.asarray(angles, float)):
        q = d.qpos.copy()
        q[adr] += row
        out.append(sysid.create_initial_state(model, q, d.qvel.copy()))
    return out


def rollout_wheels_gyro(spec, params, control, initial_state, wheels):
    """Roll the model of ``spec`` with ``params``' modifiers applied out (``mujoco.sysid.sysid_rollout``) from
    ``initial_state`` under ``control``: (sensor times, the wheel joints' speeds (n, len(wheels)) from their
    ``<joint>_speed`` sensors, the IMU gyro's z rate (n,) from the ``imu_gyro`` sensor)."""
    from mujoco import sysid
    model = sysid.apply_param_modifiers(params, spec)
    traj = sysid.sysid_rollout(model, mujoco.MjData(model), control, initial_state)[0]
    sd = traj.sensordata
    w = np.column_stack([sd.data[:, sd.signal_mapping[f"{j}_speed"][1]].ravel() for j in wheels])
    gyro = sd.data[:, sd.signal_mapping["imu_gyro"][1]][:, 2]
    return sd.times, w, gyro


def optimize(params, fn, max_iters: int, diff_step: float):
    """``mujoco.sysid.optimize`` of ``params`` on the residual ``fn`` (sysid's form) with scipy's bounded least
    squares and parallel finite differences of relative step ``diff_step``, at most ``max_iters`` evaluations, its
    per-iteration printing swallowed: (fitted ParameterDict, the optimizer's result)."""
    from mujoco import sysid
    with contextlib.redirect_stdout(io.StringIO()):       # scipy's backend prints every iteration
        return sysid.optimize(params, fn, optimizer="scipy_parallel_fd", verbose=False, max_iters=max_iters,
                              diff_step=diff_step, x_scale=1.0)


def iid_halfwidth(r: np.ndarray, J: np.ndarray, level: float) -> np.ndarray:
    """``mujoco.sysid.calculate_intervals``' half-width per column of J for residual ``r`` at coverage ``level``
    (iid residuals; infinite along the Jacobian's near-null directions)."""
    from mujoco import sysid
    _, iid = sysid.calculate_intervals([r], J, alpha=1 - level)
    return np.asarray(iid, float)


def compiled_fit_values(scene_xml: str | Path, base_scene_xml: str | Path, actuator: str, wheel: str) -> dict:
    """The fitted parameters as the MJCF ``scene_xml`` compiles them: actuator ``actuator``'s gain, joint
    ``wheel``'s damping, the floor geom's sliding friction and body ``base_link``'s mass, and ``base_mass_of_base``
    the same body's mass in ``base_scene_xml`` (the model the folder was written from)."""
    m = mujoco.MjModel.from_xml_path(str(scene_xml))
    a = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, actuator)
    j = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, wheel)
    base = mujoco.MjModel.from_xml_path(str(base_scene_xml))
    b = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "base_link")
    return {"wheel_kv": m.actuator_gainprm[a, 0], "wheel_damping": m.dof_damping[m.jnt_dofadr[j]],
            "floor_friction": m.geom_friction[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "floor"), 0],
            "base_link_mass": m.body_mass[b], "base_mass_of_base": base.body_mass[b]}
