within ArmExo.Interfaces;
partial model PartialJointFriction "Friction in n joints: velocity in, friction torque out"
  extends ArmExo.Icons.Block;
  parameter Integer n = 2 "Number of joints";
  input ArmExo.Units.AngularVelocity w[n] "Velocity of the side friction acts on";
  output ArmExo.Units.Torque tau_f[n] "Friction torque (opposes w)";
  annotation (Documentation(info = "<html><p>Base of joint friction models: the velocity of the side friction acts on in, the friction torque out. Extended by <a href=\"modelica://ArmExo.Components.LuGreFriction\">LuGreFriction</a>.</p></html>"));
end PartialJointFriction;
