within ArmExo.Interfaces;
partial model PartialArmImpedance "Joint impedance of an n-DOF arm: motion in, torque out"
  extends ArmExo.Icons.Block;
  parameter Integer n = 2 "Number of joints";
  input ArmExo.Units.Angle theta[n] "Joint angles, deviation from the posture";
  input ArmExo.Units.AngularVelocity w[n] "Joint velocities";
  input ArmExo.Units.AngularAcceleration a[n] "Joint accelerations";
  output ArmExo.Units.Torque tau[n] "Torque applied to the arm";
  annotation (Documentation(info = "<html><p>Base of arm impedance models: the joint motion (angle, velocity, acceleration, deviations from the posture) in, the torque applied to the arm out. Extended by <a href=\"modelica://ArmExo.Components.LinearArmImpedance\">LinearArmImpedance</a>.</p></html>"));
end PartialArmImpedance;
