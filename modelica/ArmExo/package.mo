within;
package ArmExo "2-DOF exoskeleton coupled to a linear human arm impedance: the plant of record"
  extends ArmExo.Icons.Package;

  annotation (
    version = "0.1.0",
    Documentation(info = "<html>
<p>Modelica model of record of the co-simulation project's plant: a serial 2-link planar
exoskeleton (configuration-dependent inertia and Coriolis terms) rigidly coupled to a linear
n-DOF human arm joint impedance, with LuGre friction in the robot joints and the plant-side
unmodelled effects of <code>docs/spec/effects.md</code>, each off by default.</p>
<p>Top-level plant: <a href=\"modelica://ArmExo.ArmExoPlant\">ArmExoPlant</a> (the FMU contract:
input <code>tau_m[n]</code>, outputs <code>theta[n]</code>, <code>tau_h[n]</code>,
<code>omega[n]</code>). Its component and parameter names equal the variable names of the
C FMU <code>fmus/ArmExoPlant</code> (e.g. <code>arm.M_h[1,2]</code>, <code>friction.Fc[1]</code>,
<code>actuator_lag.time_constant_s</code>), so an FMU exported from this package keeps the
contract.</p>
<p>Standalone: the package does not need the Modelica Standard Library; the SI types it uses
are declared in <a href=\"modelica://ArmExo.Units\">ArmExo.Units</a> with the MSL names.</p>
<p>References: H. Kang and L.-Q. Zhang, robust identification of multi-joint human arm
impedance based on dynamics decomposition (the simulation study); C. Canudas de Wit,
H. Olsson, K. J. Astrom and P. Lischinsky, A new model for control of systems with friction,
IEEE Transactions on Automatic Control 40(3), 419-425, 1995 (LuGre).</p>
</html>"));
end ArmExo;
