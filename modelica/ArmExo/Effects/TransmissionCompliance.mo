within ArmExo.Effects;
model TransmissionCompliance "Spring-damper between motor (side a) and link (side b)"
  extends ArmExo.Interfaces.PartialCompliance;
  parameter ArmExo.Units.RotationalSpringConstant k_t[n](each min = 0) = fill(0, n) "Stiffness (0: rigid, off)";
  parameter ArmExo.Units.RotationalDampingConstant c_t[n](each min = 0) = fill(0, n) "Damping";
  final parameter Boolean on = min(k_t) > 0 "Compliant transmission in every joint (a run-time switch, not structural)";
equation
  tau = k_t .* (phi_a - phi_b) + c_t .* (w_a - w_b);
  annotation (Documentation(info = "<html>
<p>tau_t = k_t (q_mot - q_link) + c_t (q_mot' - q_link'). When on, the motor inertia Jm moves
with the motor side: Jm q_mot'' = tau_act - tau_f(q_mot') - tau_t, friction acts on the motor
side, the encoder reads the motor side and the link side keeps M_r without Jm. In this
Modelica model the effect is on for all joints or none (k_t > 0 everywhere); the C FMU also
allows it per joint.</p>
</html>"));
end TransmissionCompliance;
