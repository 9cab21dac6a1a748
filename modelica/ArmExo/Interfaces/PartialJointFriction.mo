within ArmExo.Interfaces;
partial model PartialJointFriction "Friction in n joints: velocity in, friction torque out"
  extends ArmExo.Icons.Block;
  parameter Integer n = 2 "Number of joints";
  input ArmExo.Units.AngularVelocity w[n] "Velocity of the side friction acts on";
  output ArmExo.Units.Torque tau_f[n] "Friction torque (opposes w)";
end PartialJointFriction;
