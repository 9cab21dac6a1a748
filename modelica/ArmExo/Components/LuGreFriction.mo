within ArmExo.Components;
model LuGreFriction "LuGre friction in each of n joints (Canudas de Wit et al. 1995)"
  extends ArmExo.Interfaces.PartialJointFriction;
  parameter ArmExo.Units.Torque Fc[n] = fill(0, n) "Coulomb friction torque (0 with Fs = 0: no LuGre)";
  parameter ArmExo.Units.Torque Fs[n] = fill(0, n) "Static (stiction) friction torque, Fs >= Fc";
  parameter ArmExo.Units.RotationalDampingConstant sigma2[n] = fill(0, n) "Viscous friction coefficient";
  parameter ArmExo.Units.RotationalSpringConstant sigma0(min = 0) = 1.0e3 "Bristle stiffness";
  parameter ArmExo.Units.RotationalDampingConstant sigma1(min = 0) = 1.0 "Bristle damping";
  parameter ArmExo.Units.AngularVelocity ws(min = 0) = 0.01 "Stribeck velocity";
  final parameter Boolean lugre = max(Fs) > 0 "true: LuGre law (every Fc must be > 0), false: viscous only"
    annotation (Evaluate = true);
  ArmExo.Units.Angle z[n](each start = 0, each fixed = true) "Bristle deflection";
  ArmExo.Units.Torque g[n] "Stribeck curve g(w)";
equation
  if lugre then
    for j in 1:n loop
      g[j] = Fc[j] + (Fs[j] - Fc[j])*exp(-(w[j]/ws)^2);
      der(z[j]) = w[j] - sigma0*abs(w[j])*z[j]/g[j];
      tau_f[j] = sigma0*z[j] + sigma1*der(z[j]) + sigma2[j]*w[j];
    end for;
  else
    for j in 1:n loop
      g[j] = Fc[j];
      der(z[j]) = 0;
      tau_f[j] = sigma2[j]*w[j];
    end for;
  end if;
  annotation (Documentation(info = "<html>
<p>LuGre friction model (C. Canudas de Wit, H. Olsson, K. J. Astrom, P. Lischinsky, A new
model for control of systems with friction, IEEE Trans. Automatic Control 40(3):419-425, 1995),
per joint j:</p>
<pre>
  g(w)  = Fc + (Fs - Fc) exp(-(w/ws)^2)
  z'    = w - sigma0 |w| z / g(w)
  tau_f = sigma0 z + sigma1 z' + sigma2 w
</pre>
<p>With Fs = 0 for every joint (friction level 0, or pure viscous friction) the bristle law
is not used: tau_f = sigma2 w and z stays 0 (g would be 0). Levels: docs/spec/reference.md
section 4.</p>
</html>"));
end LuGreFriction;
