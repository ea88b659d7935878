"""bigcbf: BIG-CBF navigation for a Mecanum robot in MuJoCo, with a digital twin.

Layers (a lower layer never imports a higher one; see ../shared/DESIGN.md):
cli > bench > episode > sim > {perception, control} > {params, types}.
"""
import os
from pathlib import Path

# Offscreen rendering without a display (must be set before mujoco is imported anywhere).
os.environ.setdefault("MUJOCO_GL", "egl")

__version__ = "0.1.0"

#: Repository root (assets/ and scenarios/ live here; the project is installed editable).
ROOT = Path(__file__).resolve().parent.parent
ASSETS = ROOT / "assets"
SCENARIOS = ROOT / "scenarios"
RENDERS = ROOT / "renders"
