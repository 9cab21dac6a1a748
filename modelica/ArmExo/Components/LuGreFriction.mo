within ArmExo.Components;
model LuGreFriction "LuGre friction in each of n joints (Canudas de Wit et al. 1995)"
  extends ArmExo.Interfaces.PartialJointFriction;
  parameter ArmExo.Units.Torque Fc[n] = fill(0, n) "Coulomb friction torque (0 with Fs = 0: no LuGre)";
  parameter ArmExo.Units.Torque Fs[n] = fill(0, n) "Static (stiction) friction torque, Fs >= Fc";
  parameter ArmExo.Units.RotationalDampingConstant sigma2[n] = fill(0, n) "Viscous friction coefficient";
  parameter ArmExo.Units.RotationalSpringConstant sigma0(min = 0) = 1.0e3 "Bristle stiffness";
  parameter ArmExo.Units.RotationalDampingConstant sigma1(min = 0) = 1.0 "Bristle damping";
  parameter ArmExo.Units.AngularVelocity ws(min = 0) = 0.01 "Stribeck velocity";
  ArmExo.Units.Angle z[n](each start = 0, each fixed = true) "Bristle deflection (stays 0 in a joint without LuGre)";
  ArmExo.Units.Torque g[n] "Stribeck curve g(w)";
equation
  // joint j follows the LuGre law when Fs[j] > 0 (then Fc[j] > 0 is required), else it is
  // viscous only; a run-time switch per joint, not a structural one
  for j in 1:n loop
    g[j] = if Fs[j] > 0 then Fc[j] + (Fs[j] - Fc[j])*exp(-(w[j]/ws)^2) else Fc[j];
    der(z[j]) = if Fs[j] > 0 then w[j] - sigma0*abs(w[j])*z[j]/g[j] else 0;
    tau_f[j] = (if Fs[j] > 0 then sigma0*z[j] + sigma1*der(z[j]) else 0) + sigma2[j]*w[j];
  end for;
  annotation (Documentation(info = "<html>
<p>LuGre friction model (C. Canudas de Wit, H. Olsson, K. J. Astrom, P. Lischinsky, A new
model for control of systems with friction, IEEE Trans. Automatic Control 40(3):419-425, 1995),
per joint j:</p>
<pre>
  g(w)  = Fc + (Fs - Fc) exp(-(w/ws)^2)
  z'    = w - sigma0 |w| z / g(w)
  tau_f = sigma0 z + sigma1 z' + sigma2 w
</pre>
<p>In a joint with Fs = 0 (friction level 0, or pure viscous friction) the bristle law
is not used: tau_f = sigma2 w and z stays 0 (g would be 0). Levels: docs/spec/reference.md
section 4.</p>
</html>"));
end LuGreFriction;
