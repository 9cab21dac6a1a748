"""The labsim recording the segment tests share: 14 s at 1 kHz, PD servo, a noise
perturbation to 40 Hz, K switching 40 <-> 160 N m/rad every 2 s."""

import labsim


def switching_trial():
    """A fresh trialformat.Trial of that recording (callers may change it)."""
    spec = labsim.RecordingSpec(
        duration_s=14.0, fs=1000.0, seed=11,
        perturbation=labsim.Perturbation(kind="noise", amplitude_rad=0.02,
                                         band_hz=[0.0, 40.0]),
        servo=labsim.Servo(kind="pd", f_hz=80.0, damping=0.8),
        limb=labsim.Limb(K=40.0, B=1.2, I=0.015,
                         K_var=labsim.Variation(time="switching", ratio=4.0, period_s=4.0,
                                                phase_s=0.37)))
    return labsim.simulate(spec).trial
