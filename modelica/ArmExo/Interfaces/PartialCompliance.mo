within ArmExo.Interfaces;
partial model PartialCompliance "Torque between two sides a and b of n joints, from their relative motion"
  extends ArmExo.Icons.Block;
  parameter Integer n = 2 "Number of joints";
  input ArmExo.Units.Angle phi_a[n] "Angle of side a";
  input ArmExo.Units.AngularVelocity w_a[n] "Velocity of side a";
  input ArmExo.Units.Angle phi_b[n] "Angle of side b";
  input ArmExo.Units.AngularVelocity w_b[n] "Velocity of side b";
  output ArmExo.Units.Torque tau[n] "Torque from side a to side b";
  annotation (Documentation(info = "<html><p>Base of the spring-dampers between two sides of each joint (motor/link, link/arm): relative motion in, torque out.</p></html>"));
end PartialCompliance;
