within ArmExo.Examples;
model SumOfSinesFriction "SumOfSines with LuGre friction level 3"
  extends ArmExo.Examples.SumOfSines(plant(friction(
    Fc = {0.4, 0.4}, Fs = {0.6, 0.6}, sigma2 = {0.08, 0.08})));
  annotation (experiment(StartTime = 0, StopTime = 2, Interval = 0.001));
end SumOfSinesFriction;
