within ArmExo.Examples;
model GravityHold "Tilted plane: the actuators apply G(q), the posture is held"
  extends ArmExo.Icons.Block;
  ArmExo.ArmExoPlant plant(gravity(tilt_deg = 30));
equation
  plant.tau_m = plant.robot.G;
  annotation (experiment(StartTime = 0, StopTime = 1, Interval = 0.001),
    Documentation(info = "<html><p>theta stays 0: the static torque at the posture is G(q0).</p></html>"));
end GravityHold;
