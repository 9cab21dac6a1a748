within ArmExo.Examples;
model SumOfSines3Effects "SumOfSines3 with every plant-side effect on at once, and friction level 2 (joint 3: 0.25 x)"
  extends ArmExo.Examples.SumOfSines3(plant(
    friction(Fc = {0.2, 0.2, 0.05}, Fs = {0.3, 0.3, 0.075}, sigma2 = {0.04, 0.04, 0.01}),
    actuator_lag(time_constant_s = 0.003),
    transmission_compliance(k_t = {300, 300, 100}, c_t = {0.5, 0.5, 0.1}),
    interface_compliance(k_s = {400, 400, 100}, c_s = {2, 2, 0.3}),
    gravity(tilt_deg = 10),
    inertia_mismatch(scale = 0.8),
    torque_sensor_lag(time_constant_s = 0.002)));
  annotation (experiment(StartTime = 0, StopTime = 2, Interval = 0.001));
end SumOfSines3Effects;
