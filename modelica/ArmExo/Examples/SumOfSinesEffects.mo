within ArmExo.Examples;
model SumOfSinesEffects "SumOfSines with every plant-side effect on at once, and friction level 2"
  extends ArmExo.Examples.SumOfSines(plant(
    friction(Fc = {0.2, 0.2}, Fs = {0.3, 0.3}, sigma2 = {0.04, 0.04}),
    actuator_lag(time_constant_s = 0.003),
    transmission_compliance(k_t = {300, 300}, c_t = {0.5, 0.5}),
    interface_compliance(k_s = {400, 400}, c_s = {2, 2}),
    gravity(tilt_deg = 10),
    inertia_mismatch(scale = 0.8),
    torque_sensor_lag(time_constant_s = 0.002)));
  annotation (experiment(StartTime = 0, StopTime = 2, Interval = 0.001));
end SumOfSinesEffects;
