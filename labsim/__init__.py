"""labsim: an independent simulator of lab recordings (position-servo experiments).

The truth of the project's blind validations: recordings of a joint (one or two) on a
position servo, simulated by models whose forms differ from the fits' (servo dynamics
loaded by the limb, time- and state-varying K, B, I, nonlinear springs, reflexes of other
dynamics, wobbling masses, footplate friction, sensor filters, coloured noise, the
subject's own torque, slow imposed movements), stored the ways labs store them. It
imports nothing of ``diagnosis`` or ``estimation`` (numpy, scipy and ``trialformat``
only). Continuous-time dynamics are stepped exactly for inputs linear between the points
of a fine grid (``oversample`` x fs) by a modal first-order-hold recursion
(:mod:`labsim.lti`), the nonlinear limb by waveform relaxation with Anderson mixing
(:mod:`labsim.servo`); then anti-alias filtering and sampling at fs (:mod:`labsim.sensors`).

API (stable; docs/labsim.md)::

    spec = labsim.RecordingSpec(duration_s=60, fs=1000, n_dof=1, seed=1,
                                perturbation=labsim.Perturbation(kind="noise"),
                                servo=labsim.Servo(kind="pd"), limb=labsim.Limb(K=80),
                                reflex=None, wobbling=None, footplate=None,
                                voluntary=None, movement=None, sensors=labsim.Sensors(),
                                record_reference=True)
    rec = labsim.simulate(spec)      # labsim.Recording: .trial, .truth, .spec
    labsim.write(rec, folder, name, representation="csv17")   # + NAME.truth.json
    spec = labsim.draw("saturating_drift+reflex", np.random.default_rng(3))
    truth = labsim.read_truth("folder/NAME.truth.json")
    labsim.write_set("runs/set", ["nominal", "switching+reflex"], 5, seed=1,
                     representation="mixed")     # a blind validation set

``python3 -m labsim --kind KIND --seed S --out FOLDER`` writes one recording.
"""

from .draw import KINDS, draw
from .servo import SimulationError
from .recording import Recording, simulate
from .spec import (Channel, Filter, Footplate, Limb, Movement, Perturbation, RecordingSpec,
                   Reflex, Sensors, Servo, Variation, Voluntary, WobblingMass,
                   spec_from_dict, spec_to_dict)
from .write import (LAB_REPRESENTATIONS, REPRESENTATIONS, read_truth, truth_document, write,
                    write_set)

__all__ = ["Channel", "Filter", "Footplate", "KINDS", "Limb", "Movement", "Perturbation",
           "REPRESENTATIONS", "Recording", "RecordingSpec", "Reflex", "Sensors", "Servo",
           "SimulationError", "Variation", "Voluntary", "WobblingMass", "draw", "read_truth",
           "simulate", "spec_from_dict", "spec_to_dict", "truth_document", "write",
           "write_set", "LAB_REPRESENTATIONS"]
