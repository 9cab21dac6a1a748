within ArmExo.Components;
model LinearArmImpedance "Linear n-DOF human arm joint impedance tau = M_h a + B_h w + K_h theta"
  extends ArmExo.Interfaces.PartialArmImpedance;
  parameter ArmExo.Units.Inertia M_h[n, n] = [0.187, 0.084; 0.079, 0.060] "Inertia matrix (as printed, not symmetrised)";
  parameter ArmExo.Units.RotationalDampingConstant B_h[n, n] = [0.651, 0.239; 0.236, 0.407] "Damping matrix (as printed)";
  parameter ArmExo.Units.RotationalSpringConstant K_h[n, n] = [7.967, 3.187; 1.663, 6.901] "Stiffness matrix (as printed)";
equation
  tau = M_h*a + B_h*w + K_h*theta;
  annotation (Documentation(info = "<html>
<p>Linear joint impedance of the human arm about the posture theta0 (Kang and Zhang, eqs. 1-3):</p>
<pre>  tau = M_h theta'' + B_h theta' + K_h theta,   theta = deviation from theta0</pre>
<p>The matrices are used as printed in the paper's Table I (they are not symmetric). The
defaults are the 2-DOF values of Table I; for another n give matrices of size n x n.</p>
</html>"));
end LinearArmImpedance;
