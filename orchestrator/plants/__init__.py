"""Plant FMUs the orchestrator ships besides the reference C plant (package ``fmus``).

:func:`build_linear_arm_fmu` builds ``LinearArmPlant.fmu`` with pythonfmu (a test
dependency, imported only here) from :mod:`orchestrator.plants.linear_arm`.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

LINEAR_ARM_SOURCE = Path(__file__).with_name("linear_arm.py")


def _configuration_block(M_h, B_h, K_h, M_r, posture_deg) -> str:
    n = len(posture_deg)
    tup = lambda m: repr(tuple(tuple(float(v) for v in row) for row in np.asarray(m)))  # noqa: E731
    return "\n".join([
        "# --- configuration (build_linear_arm_fmu rewrites this block for n joints) ---",
        f"_M_H = {tup(M_h)}", f"_B_H = {tup(B_h)}", f"_K_H = {tup(K_h)}", f"_M_R = {tup(M_r)}",
        f"_POSTURE_DEG = {tuple(float(v) for v in posture_deg)!r}", f"_N = {n}",
        "# --- end of configuration ---"])


def build_linear_arm_fmu(dest_dir, *, omit_outputs=(), module_name="linear_arm",
                         arm=None, M_r=None, posture_deg=None) -> Path:
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
    arm : (M_h, B_h, K_h), optional
        Arm matrices (n, n) [kg m^2], [N m s/rad], [N m/rad] of an n-joint plant; with
        ``M_r`` (n, n) [kg m^2] and ``posture_deg`` (n,). Default: the shipped two-joint
        configuration (Table I).

    Raises
    ------
    ValueError
        A matrix whose shape does not match n = len(posture_deg), naming it.

    Returns
    -------
    Path
        The FMU file.
    """
    from pythonfmu import FmuBuilder  # test dependency: import only when building

    dest_dir = Path(dest_dir)
    dest_dir.mkdir(parents=True, exist_ok=True)
    text = LINEAR_ARM_SOURCE.read_text()
    if arm is not None:
        n = len(posture_deg)
        for name, m in zip(("M_h", "B_h", "K_h", "M_r"), (*arm, M_r)):
            if np.shape(m) != (n, n):
                raise ValueError(f"linear plant matrix {name} has shape {np.shape(m)}; "
                                 f"expected ({n}, {n}) for {n} joints")
        start = text.index("# --- configuration")
        end = text.index("# --- end of configuration ---") + len("# --- end of configuration ---")
        text = text[:start] + _configuration_block(*arm, M_r, posture_deg) + text[end:]
    with tempfile.TemporaryDirectory(prefix="linear_arm_src_") as tmp:
        script = Path(tmp) / f"{module_name}.py"
        script.write_text(text)
        newargs = {"omit_outputs": tuple(omit_outputs)} if omit_outputs else None
        fmu = FmuBuilder.build_FMU(script, dest=dest_dir / f"{module_name}.fmu",
                                   newargs=newargs, needsExecutionTool="false")
    return Path(fmu)
