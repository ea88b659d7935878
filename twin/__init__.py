"""The digital twin: calibrate the shared-uncertainty terms of Eq. (15) from robot logs, record calibration drives
in the simulator, replay logged commands through the MuJoCo model.

Builds on bigcbf (log I/O, simulator, parameter types); nothing in bigcbf imports twin except the command line,
which loads it lazily inside ``bigcbf record``, ``bigcbf calibrate`` and ``bigcbf replay``.

Equation numbers follow the project's numbering (see ``bigcbf/control/__init__.py``): Eq. (1) the execution model
v = A u + d + r [eq:execution]; Eq. (15) the uncertainty radius m_i with tau95, e_exec(u) and e_ZOH
[eq:uncertainty_margin].
"""
