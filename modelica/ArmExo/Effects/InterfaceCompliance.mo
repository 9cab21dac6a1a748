within ArmExo.Effects;
model InterfaceCompliance "Spring-damper (the cuff) between robot link (side a) and arm (side b)"
  extends ArmExo.Interfaces.PartialCompliance;
  parameter ArmExo.Units.RotationalSpringConstant k_s[n](each min = 0) = fill(0, n) "Stiffness (0: rigid cuff, off)";
  parameter ArmExo.Units.RotationalDampingConstant c_s[n](each min = 0) = fill(0, n) "Damping";
  final parameter Boolean on = min(k_s) > 0 "Compliant cuff in every joint (a run-time switch, not structural)";
equation
  tau = k_s .* (phi_a - phi_b) + c_s .* (w_a - w_b);
  annotation (Documentation(info = "<html>
<p>tau_h = k_s (theta - theta_h) + c_s (theta' - theta_h'); the arm has its own states
theta_h and M_h theta_h'' + B_h theta_h' + K_h theta_h = tau_h. The encoder reads the robot,
the sensor reads tau_h. Off (rigid, theta_h = theta) when k_s = 0.</p>
</html>"));
end InterfaceCompliance;
