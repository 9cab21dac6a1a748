within ArmExo.Interfaces;
partial model PartialPlant "The plant contract (docs/spec/plant-contract.md)"
  extends ArmExo.Icons.Block;
  parameter Integer n = 2 "Number of joints";
  input ArmExo.Units.Torque tau_m[n] "Actuator torque command";
  output ArmExo.Units.Angle theta[n] "Joint angle at the encoder, deviation from the posture";
  output ArmExo.Units.Torque tau_h[n] "Torque robot -> arm at the torque sensor";
  output ArmExo.Units.AngularVelocity omega[n] "Joint velocity at the encoder";
end PartialPlant;
