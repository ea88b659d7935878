"""Parameters: frozen dataclasses with documented units, loaded from and saved to TOML."""
from .robot import RobotProfile
from .toml_io import from_dict, load, load_toml, save, to_dict

__all__ = ["RobotProfile", "from_dict", "load", "load_toml", "save", "to_dict"]
