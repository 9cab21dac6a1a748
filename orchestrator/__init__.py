"""The co-simulation master: plant FMUs, IMBIC at 1 kHz, trials, the paper grid, the CLI.

Public API::

    from orchestrator import Setup, simulate_trial, make_perturbation, Plant, run_grid
"""

_EXPORTS = {
    'IMBIC': '.controller',
    'ControllerConfig': '.controller',
    'CATALOGUE': '.effects',
    'parse_effects': '.effects',
    'ContractError': '.errors',
    'DivergenceError': '.errors',
    'EffectError': '.errors',
    'FMUCallError': '.errors',
    'ParameterError': '.errors',
    'PlantFileError': '.errors',
    'PlantWarning': '.errors',
    'RateError': '.errors',
    'SetupError': '.errors',
    'grid_seed': '.grid',
    'grid_tasks': '.grid',
    'parse_dof': '.grid',
    'run_grid': '.grid',
    'trial_name': '.grid',
    'paper_plan': '.paper',
    'run_paper': '.paper',
    'make_perturbation': '.perturbation',
    'Plant': '.plant',
    'check_contract': '.plant',
    'Setup': '.setup',
    'default_fmu_path': '.trial',
    'get_plant': '.trial',
    'simulate_plant': '.trial',
    'simulate_trial': '.trial',
}

__all__ = ["Setup", "simulate_trial", "make_perturbation", "Plant", "run_grid", "IMBIC",
           "ControllerConfig", "CATALOGUE", "parse_effects", "ContractError",
           "DivergenceError", "EffectError", "FMUCallError", "ParameterError",
           "PlantFileError", "PlantWarning", "RateError", "SetupError", "grid_tasks",
           "grid_seed", "parse_dof", "paper_plan", "run_paper",
           "trial_name", "check_contract", "default_fmu_path", "get_plant", "simulate_plant"]


from trialformat.firstuse import first_use  # noqa: E402

__getattr__, __dir__ = first_use(__name__, globals(), _EXPORTS)
