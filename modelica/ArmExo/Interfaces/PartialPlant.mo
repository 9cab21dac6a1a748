within ArmExo.Interfaces;
partial model PartialPlant "The plant contract (docs/spec/plant-contract.md)"
  extends ArmExo.Icons.Block;
  parameter Integer n = 2 "Number of joints";
  input ArmExo.Units.Torque tau_m[n] "Actuator torque command";
  output ArmExo.Units.Angle theta[n] "Joint angle at the encoder, deviation from the posture";
  output ArmExo.Units.Torque tau_h[n] "Torque robot -> arm at the torque sensor";
  output ArmExo.Units.AngularVelocity omega[n] "Joint velocity at the encoder";
  annotation (Documentation(info = "<html><p>The plant contract of docs/spec/plant-contract.md: input tau_m[n] (N.m, held over each communication step by a co-simulation master), outputs theta[n] (rad, encoder, deviation from the posture), tau_h[n] (N.m, robot to arm at the sensor), omega[n] (rad/s, encoder). n is the number of joints.</p></html>"));
end PartialPlant;
