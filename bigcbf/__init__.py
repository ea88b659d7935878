"""bigcbf: BIG-CBF navigation for a Mecanum robot in MuJoCo, with a digital twin.

Layers (a lower layer never imports a higher one; see ../shared/DESIGN.md):
cli > bench > episode > sim > {perception, control} > {params, types}.
"""
import os
from pathlib import Path

# Offscreen rendering without a display (must be set before mujoco is imported anywhere).
os.environ.setdefault("MUJOCO_GL", "egl")

__version__ = "0.1.0"

#: The package's own data (shipped in the wheel): the MJCF robot model, the scenario files and the
#: robot and stack profiles. The repository's
#: top-level ``assets`` and ``scenarios`` are symbolic links to these folders.
PACKAGE = Path(__file__).resolve().parent
ASSETS = PACKAGE / "assets"
SCENARIOS = PACKAGE / "scenarios"
#: Robot profiles (hardware imperfections and sensor models) shipped with the package, and the stack's
#: uncertainty profiles calibrated from them by the twin (``bigcbf profile simulate``).
PROFILES = PACKAGE / "profiles"
#: The checkout's root when running from a source tree (tests, scripts); not meaningful in an installed wheel.
ROOT = PACKAGE.parent
#: Default folder for videos: ``renders/`` of the current directory.
RENDERS = Path("renders")
