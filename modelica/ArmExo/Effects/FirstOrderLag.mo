within ArmExo.Effects;
model FirstOrderLag "First-order lag T y' = u - y per channel; y = u when T = 0"
  extends ArmExo.Interfaces.PartialVectorBlock;
  parameter ArmExo.Units.Time time_constant_s(min = 0) = 0 "Time constant T (0: off, y = u)";
  final parameter Boolean on = time_constant_s > 0 "Lag in use (a run-time switch, not structural)";
  Real x[n](each start = 0, each fixed = true) "Lag state (0 at the start; stays 0 when off)";
equation
  for j in 1:n loop
    der(x[j]) = if on then (u[j] - x[j])/time_constant_s else 0;
    y[j] = if on then x[j] else u[j];
  end for;
  annotation (Documentation(info = "<html>
<p>Used as <code>actuator_lag</code> (T_a tau_act' = tau_m - tau_act) and as
<code>torque_sensor_lag</code> (T_s y' = tau_h - y, the sensor reads y). Off (y = u) when the
time constant is 0.</p>
</html>"));
end FirstOrderLag;
