"""The digital twin: calibrate the shared-uncertainty terms of eq:uncertainty_margin (21) from robot logs, record
calibration drives in the simulator, replay logged commands through the MuJoCo model.

Builds on bigcbf (log I/O, simulator, parameter types); nothing in bigcbf imports twin except the command line,
which loads it lazily inside ``bigcbf record``, ``bigcbf calibrate`` and ``bigcbf replay``.

Equations are cited as ``eq:label (N)``, the paper's LaTeX label and the number it prints (see
``bigcbf/control/__init__.py``): eq:execution (1) the execution model v = A u + d + r; eq:uncertainty_margin (21)
the uncertainty radius m_i with tau95, e_exec(u) and e_ZOH.

The public Python API (loaded on first use; ``import twin.calibrate`` alone never imports MuJoCo)::

    import twin
    cal = twin.calibrate_log("drive.mcap")             # -> twin.Calibration (tau95, A, d, e_exec, e_ZOH, ...)
    twin.write_profile(cal, "calibrated.toml")         # the uncertainty profile for bigcbf run --profile
    rep = twin.replay_log("drive.mcap", "calibrated.toml")   # -> twin.ReplayResult (per-model RMSE and drift)
    twin.record_calibration(bigcbf.params.RobotProfile(latency_s=0.08), "drive.mcap", duration_s=60.0)
"""

#: name -> module of the public API, imported on first access (PEP 562)
_API = {"calibrate_log": "calibrate", "calibrate_series": "calibrate", "read_log": "calibrate",
        "write_profile": "calibrate", "Calibration": "calibrate", "CalibrationOptions": "calibrate",
        "replay_log": "replay", "ReplayResult": "replay", "ReplayOptions": "replay",
        "record_calibration": "record"}


def __getattr__(name: str):
    mod = _API.get(name)
    if mod is None:
        raise AttributeError(f"module 'twin' has no attribute {name!r}")
    import importlib
    return getattr(importlib.import_module(f"{__name__}.{mod}"), name)


def __dir__():
    return sorted(set(globals()) | set(_API))
