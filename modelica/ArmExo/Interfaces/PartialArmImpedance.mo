within ArmExo.Interfaces;
partial model PartialArmImpedance "Joint impedance of an n-DOF arm: motion in, torque out"
  extends ArmExo.Icons.Block;
  parameter Integer n = 2 "Number of joints";
  input ArmExo.Units.Angle theta[n] "Joint angles, deviation from the posture";
  input ArmExo.Units.AngularVelocity w[n] "Joint velocities";
  input ArmExo.Units.AngularAcceleration a[n] "Joint accelerations";
  output ArmExo.Units.Torque tau[n] "Torque applied to the arm";
end PartialArmImpedance;
