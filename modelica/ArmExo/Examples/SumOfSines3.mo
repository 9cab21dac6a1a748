within ArmExo.Examples;
model SumOfSines3 "Three-link plant driven by a sum of sines (the cross-check with the C FMU ArmExoPlant3)"
  extends ArmExo.Icons.Block;
  parameter ArmExo.Units.Torque A[3] = {0.5, 0.3, 0.06} "Amplitudes";
  parameter Real f[3](each unit = "Hz") = {1.5, 2.5, 3.5} "Frequencies";
  parameter ArmExo.Units.Torque A2[3] = {0.2, 0.15, 0.03} "Amplitudes of the second sine";
  parameter Real f2[3](each unit = "Hz") = {7.0, 11.0, 5.0} "Frequencies of the second sine";
  ArmExo.ArmExoPlant3 plant;
equation
  plant.tau_m = {A[j]*sin(2*3.141592653589793*f[j]*time) + A2[j]*sin(2*3.141592653589793*f2[j]*time) for j in 1:3};
  annotation (experiment(StartTime = 0, StopTime = 2, Interval = 0.001),
    Documentation(info = "<html>
<p>tau_m[j] = A[j] sin(2 pi f[j] t) + A2[j] sin(2 pi f2[j] t). Used by
tests/plant/test_modelica_agreement.py.</p></html>"));
end SumOfSines3;
