"""The co-simulation master: plant FMUs, IMBIC at 1 kHz, trials, the paper grid, the CLI.

Public API::

    from orchestrator import Setup, simulate_trial, make_perturbation, Plant, run_grid
"""

from .controller import IMBIC, ControllerConfig
from .effects import CATALOGUE, parse_effects
from .errors import (ContractError, DivergenceError, EffectError, FMUCallError,
                     ParameterError, PlantFileError, PlantWarning, RateError, SetupError)
from .grid import grid_seed, grid_tasks, parse_dof, run_grid, trial_name
from .paper import paper_plan, run_paper
from .perturbation import make_perturbation
from .plant import Plant, check_contract
from .setup import Setup
from .trial import default_fmu_path, get_plant, simulate_plant, simulate_trial

__all__ = ["Setup", "simulate_trial", "make_perturbation", "Plant", "run_grid", "IMBIC",
           "ControllerConfig", "CATALOGUE", "parse_effects", "ContractError",
           "DivergenceError", "EffectError", "FMUCallError", "ParameterError",
           "PlantFileError", "PlantWarning", "RateError", "SetupError", "grid_tasks",
           "grid_seed", "parse_dof", "paper_plan", "run_paper",
           "trial_name", "check_contract", "default_fmu_path", "get_plant", "simulate_plant"]
