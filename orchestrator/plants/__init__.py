"""Plant FMUs the orchestrator ships besides the reference C plant (package ``fmus``).

:func:`build_linear_arm_fmu` builds ``LinearArmPlant.fmu`` with pythonfmu (a test
dependency, imported only here) from :mod:`orchestrator.plants.linear_arm`.
"""

from __future__ import annotations

import shutil
import tempfile
from pathlib import Path

LINEAR_ARM_SOURCE = Path(__file__).with_name("linear_arm.py")


def build_linear_arm_fmu(dest_dir, *, omit_outputs=(), module_name="linear_arm") -> Path:
    """Build the linear-arm plant as an FMI 2.0 Co-Simulation FMU with pythonfmu.

    Parameters
    ----------
    dest_dir : path
        Folder to write ``<module_name>.fmu`` into (created if needed).
    omit_outputs : tuple of str
        Contract outputs to leave out, to make a plant that breaks the contract (tests).
    module_name : str
        Name of the slave module inside the FMU. Give variants distinct names: pythonfmu
        imports the module into the running interpreter, where a second FMU with the same
        module name would reuse the first one's cached module.

    Returns
    -------
    Path
        The FMU file.
    """
    from pythonfmu import FmuBuilder  # test dependency: import only when building

    dest_dir = Path(dest_dir)
    dest_dir.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="linear_arm_src_") as tmp:
        script = Path(tmp) / f"{module_name}.py"
        shutil.copy2(LINEAR_ARM_SOURCE, script)
        newargs = {"omit_outputs": tuple(omit_outputs)} if omit_outputs else None
        fmu = FmuBuilder.build_FMU(script, dest=dest_dir / f"{module_name}.fmu",
                                   newargs=newargs, needsExecutionTool="false")
    return Path(fmu)
