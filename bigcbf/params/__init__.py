"""Parameters: frozen dataclasses with documented units, loaded from and saved to TOML."""
from .perception import PerceptionParams
from .robot import RobotProfile
from .stack import (PHYSICAL, SIMULATION, ExecutionModel, StackParams, UncertaintyParams, load_stack_params,
                    save_stack_params)
from .toml_io import from_dict, load, load_toml, save, to_dict

__all__ = ["PerceptionParams",
           "RobotProfile", "ExecutionModel", "UncertaintyParams", "StackParams", "SIMULATION", "PHYSICAL",
           "load_stack_params", "save_stack_params", "from_dict", "load", "load_toml", "save", "to_dict"]
